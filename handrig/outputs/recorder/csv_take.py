"""Performance CSV: :class:`CsvTake`.

Header row ``t_s,<50 curve names>[,<4 wrist names>]``, one row per frame, values
with 6 decimals (round trip within 5e-7). Times are the loop's, as recorded.
"""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.errors import DataError
from handrig.offline.bvh import UNFINISHED_HINT
from handrig.outputs.recorder.formats import (
    Format,
    FrameLayout,
    Performance,
    TakeFormat,
    all_numbers,
    check_finite,
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

    def encode(self, t_s: float, values: NDArray[np.float64], with_wrist: bool) -> bytes:
        used = values if with_wrist else values[:_CURVES]
        return self._line_fmt % (t_s, *used.tolist())

    @classmethod
    def load(cls, p: Path) -> Performance:
        try:
            text = p.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise DataError(f"{p}: cannot read the recording: {exc}") from None
        lines = text.splitlines()
        if not lines:
            raise DataError(f"{p}: empty file: expected a header row 't_s,<curve names>'")
        header = [h.strip() for h in lines[0].split(",")]
        if header[0] != "t_s":
            raise DataError(f"{p}: line 1: the first column must be 't_s', found"
                            f" {header[0]!r}; not a handrig performance CSV")
        unknown = [h for h in header[1:] if h not in hand.CURVE_NAMES and h not in WRIST_NAMES]
        if unknown:
            raise DataError(f"{p}: line 1: unknown column {unknown[0]!r} (columns are t_s,"
                            f" the 50 curve names and optionally {WRIST_NAMES})")
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
        rows = [(n, ln) for n, ln in enumerate(lines[1:], start=2) if ln.strip()]
        if not rows:
            raise DataError(f"{p}: no frames after the header")
        width = len(header)
        try:
            data = np.array([ln.split(",") for _, ln in rows], dtype=np.float64)
            if data.ndim != 2 or data.shape[1] != width:
                raise ValueError
        except ValueError:
            _raise_bad_row(p, rows, width)
            raise
        check_finite(data, p, "line", rows[0][0])
        t_s = data[:, 0]
        back = np.flatnonzero(np.diff(t_s) < 0)
        if back.size:
            k = int(back[0]) + 1
            raise DataError(f"{p}: line {rows[k][0]}: time goes backwards"
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
        width = len(first.split(","))

        def good(line: bytes) -> bool:
            return all_numbers(line.split(b","), width)

        return FrameLayout(nl + 1, good)


def _raise_bad_row(p: Path, rows: list[tuple[int, str]], width: int) -> None:
    for n, ln in rows:
        fields = ln.split(",")
        if len(fields) != width:
            last = (f" (the last line: the file is truncated; {UNFINISHED_HINT})"
                    if n == rows[-1][0] else "")
            raise DataError(f"{p}: line {n}: {len(fields)} values, expected {width}{last}")
        for col, tok in enumerate(fields):
            try:
                float(tok)
            except ValueError:
                shown = tok.strip()
                shown = repr(shown) if len(shown) <= 24 else repr(shown[:24]) + "..."
                last = (f" (the last line: the file is cut; {UNFINISHED_HINT})"
                        if n == rows[-1][0] else "")
                raise DataError(f"{p}: line {n}, column {col + 1}: {shown} is not"
                                f" a number{last}") from None
