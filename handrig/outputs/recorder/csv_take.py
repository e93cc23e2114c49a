"""Performance CSV: :class:`CsvTake`.

Header row ``t_s,<50 curve names>[,<4 wrist names>]``, one row per frame, values
with 6 decimals (round trip within 5e-7). Each row keeps its frame's real time (the
loop's clock, seconds since the run started): rows are as far apart as the frames
were, evenly or not, and a stretch with no frames is a gap between two rows.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from pathlib import Path
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.config import bounded
from handrig.errors import DataError
from handrig.offline.bvh import UNFINISHED_HINT
from handrig.outputs.recorder.formats import (
    Emit,
    Format,
    FrameLayout,
    Performance,
    TakeFormat,
    all_numbers,
    csv_header,
)
from handrig.outputs.vmc import WRIST_NAMES

_CURVES = len(hand.CURVE_NAMES)


class CsvTake(TakeFormat):
    """A performance CSV: a row per frame with its time."""

    name: ClassVar[Format] = "csv"
    header_needs_wrist: ClassVar[bool] = True

    def __init__(self) -> None:
        self._line_fmt = b""
        self._with_wrist: bool | None = None

    def header(self, with_wrist: bool) -> bytes:
        names = csv_header(with_wrist)
        self._line_fmt = b",".join([b"%.6f"] * len(names)) + b"\n"
        self._with_wrist = with_wrist
        return (",".join(names) + "\n").encode("ascii")

    def add(self, t_s: float, values: NDArray[np.float64], with_wrist: bool,
            emit: Emit) -> None:
        used = values if with_wrist else values[:_CURVES]
        emit(self._line_fmt % (t_s, *used.tolist()), 1)

    @classmethod
    def load(cls, p: Path) -> Performance:
        what = "a handrig performance CSV"
        try:
            with p.open("rb") as f:
                lines = bounded.lines(f, p, what)
                first = next(lines, None)
                if first is None:
                    raise DataError(f"{p}: empty file: expected a header row"
                                    " 't_s,<curve names>'")
                header = check_header(first[1], p)
                width = len(header)
                blocks, line_no = _read_rows(lines, p, width)
        except OSError as exc:
            raise DataError(f"{p}: cannot read the recording: {exc.strerror}") from None
        if not blocks:
            raise DataError(f"{p}: no frames after the header")
        wrist_cols = [n for n in WRIST_NAMES if n in header]
        data = np.concatenate(blocks) if len(blocks) > 1 else blocks[0]
        at = np.concatenate(line_no)
        bad = ~np.isfinite(data)
        if bad.any():
            r, c = np.argwhere(bad)[0]
            raise DataError(f"{p}: line {at[r]}: value {data[r, c]} is not finite")
        t_s = data[:, 0]
        back = np.flatnonzero(np.diff(t_s) < 0)
        if back.size:
            k = int(back[0]) + 1
            raise DataError(f"{p}: line {at[k]}: time goes backwards"
                            f" ({t_s[k - 1]} -> {t_s[k]} s)")
        order = [header.index(n) for n in hand.CURVE_NAMES]
        poses = np.ascontiguousarray(data[:, order])
        wrist = (np.ascontiguousarray(data[:, [header.index(n) for n in WRIST_NAMES]])
                 if wrist_cols else None)
        return np.ascontiguousarray(t_s), poses, wrist

    @classmethod
    def layout(cls, head: bytes, p: Path) -> FrameLayout:
        nl = head.find(b"\n")
        first = head[: nl if nl >= 0 else len(head)].decode("ascii", errors="replace")
        if nl < 0 or not first.startswith("t_s,"):
            raise DataError(f"{p}: no header row 't_s,<curve names>': not a handrig"
                            " performance CSV, or cut before its first frame; nothing to keep")
        try:
            width = len(check_header(first.rstrip("\r"), p))
        except DataError as exc:
            raise DataError(f"{exc}: the header is damaged; nothing to keep") from None

        def good(line: bytes) -> bool:
            return all_numbers(line.split(b","), width)

        return FrameLayout(nl + 1, good, width=width, times="rising")


def check_header(line: str, p: Path) -> list[str]:
    """The column names of a performance CSV's first line; DataError naming what is wrong
    (quoting at most a short excerpt)."""
    header = [h.strip() for h in line.split(",")]
    if header[0] != "t_s":
        raise DataError(f"{p}: line 1: the first column must be 't_s', found"
                        f" {bounded.excerpt(header[0])}; not a handrig performance CSV")
    unknown = [h for h in header[1:] if h not in hand.CURVE_NAMES and h not in WRIST_NAMES]
    if unknown:
        raise DataError(f"{p}: line 1: unknown column {bounded.excerpt(unknown[0])} (columns"
                        f" are t_s, the 50 curve names and optionally {WRIST_NAMES})")
    missing = [n for n in hand.CURVE_NAMES if n not in header]
    if missing:
        raise DataError(f"{p}: line 1: {len(missing)} curve column(s) missing,"
                        f" first {missing[0]!r}")
    if len(set(header)) != len(header):
        dup = next(h for h in header if header.count(h) > 1)
        raise DataError(f"{p}: line 1: column {dup!r} appears twice")
    wrist_cols = [n for n in WRIST_NAMES if n in header]
    if wrist_cols and len(wrist_cols) != len(WRIST_NAMES):
        raise DataError(f"{p}: line 1: wrist columns must be all of {WRIST_NAMES} or"
                        f" none; found {wrist_cols}")
    return header


_BLOCK_ROWS = 4096


def _read_rows(lines: Iterator[tuple[int, str]], p: Path, width: int
               ) -> tuple[list[NDArray[np.float64]], list[NDArray[np.int64]]]:
    """The frames after the header as arrays of up to :data:`_BLOCK_ROWS` rows (the text
    of one block at a time in memory), and their line numbers."""
    blocks: list[NDArray[np.float64]] = []
    numbers: list[NDArray[np.int64]] = []
    chunk: list[tuple[int, str]] = []
    for item in itertools.chain(lines, [(0, "")]):
        if item[0] and item[1].strip():
            chunk.append(item)
            if len(chunk) < _BLOCK_ROWS:
                continue
        if not chunk:
            continue
        try:
            block = np.array([ln.split(",") for _, ln in chunk], dtype=np.float64)
            if block.ndim != 2 or block.shape[1] != width:
                raise ValueError
        except ValueError:
            try:  # whether the bad row is the last one: a cut file
                last = next((n for n, ln in lines if ln.strip()), None) is None
            except DataError:
                last = False
            _raise_bad_row(p, chunk, width, last)
            raise
        blocks.append(block)
        numbers.append(np.array([n for n, _ in chunk], dtype=np.int64))
        chunk = []
    return blocks, numbers


def _raise_bad_row(p: Path, rows: list[tuple[int, str]], width: int,
                   ends_the_file: bool) -> None:
    for n, ln in rows:
        fields = ln.split(",")
        if len(fields) != width:
            last = (f" (the last line: the file is truncated; {UNFINISHED_HINT})"
                    if ends_the_file and n == rows[-1][0] else "")
            raise DataError(f"{p}: line {n}: {len(fields)} values, expected {width}{last}")
        for col, tok in enumerate(fields):
            try:
                float(tok)
            except ValueError:
                shown = bounded.excerpt(tok.strip(), 24)
                last = (f" (the last line: the file is cut; {UNFINISHED_HINT})"
                        if ends_the_file and n == rows[-1][0] else "")
                raise DataError(f"{p}: line {n}, column {col + 1}: {shown} is not"
                                f" a number{last}") from None
