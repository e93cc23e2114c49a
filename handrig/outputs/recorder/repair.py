"""Make a take cut short by a crash or a power cut readable, and find damage: :func:`repair`.

Takes of every kind: a performance (CSV or BVH) and a glove take (the glove recording
``handrig run --record-glove`` and ``handrig record glove`` write), finished or left as
``<take>.partial``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from handrig.config.bounded import MAX_LINE_BYTES, excerpt
from handrig.devices.glove_recording import MAGIC, QUAT_COLUMNS, read_glove_recording
from handrig.errors import DataError
from handrig.outputs.recorder.formats import (
    PARTIAL_SUFFIX,
    FrameLayout,
    format_of,
    partial_path,
)
from handrig.outputs.recorder.loading import FORMAT_CLASSES, load_performance

_SCAN_BLOCK = 1 << 20
_HEAD_MAX = 1 << 20  # a BVH hierarchy is a few kilobytes
DAMAGED_SUFFIX = ".damaged"
"""Where repair puts what follows damage inside a take (nothing is thrown away)."""


@dataclass(frozen=True)
class Damage:
    """The first frame line of a take that is not a whole, sound frame, and what follows."""

    line: int
    """Its line number in the file (1-based)."""
    byte: int
    """Where it starts (bytes from the file's start)."""
    what: str
    """What is wrong with it."""
    moved_to: Path
    """Where the bytes from it to the end of the file were put."""
    bytes_moved: int


@dataclass(frozen=True)
class Repaired:
    """What :func:`repair` did: the readable file, its frames, what it cut off and the
    damage it found."""

    path: Path
    frames: int
    bytes_dropped: int
    declared_frames: int | None
    """The frame count the BVH header held before (None for CSV)."""
    damage: Damage | None = None
    kind: str = "performance"
    """"performance" or "glove take"."""

    def describe(self) -> str:
        if self.damage is not None:
            d = self.damage
            return (f"{self.path}: damaged at line {d.line} (byte {d.byte}): {d.what}; kept"
                    f" the {self.frames} whole frames before it, and moved the"
                    f" {d.bytes_moved} bytes from there on to {d.moved_to}")
        cut = (f"cut {self.bytes_dropped} bytes of an unfinished frame" if self.bytes_dropped
               else "nothing cut")
        was = ("" if self.declared_frames is None or self.declared_frames == self.frames
               else f", the header said {self.declared_frames}")
        return f"{self.path}: {self.frames} whole frames, every one checked ({cut}{was})"


def repair(path: str | Path) -> Repaired:
    """Check every frame of a take and make it readable, in place, streaming (any length).

    Each frame line must hold the header's number of values, all numbers, and (CSV, glove
    take) a time that does not go back. An unfinished last line (a cut, the zeros a power
    cut can leave) is truncated. A bad line before that is damage: the whole frames
    before it are kept, and everything from it on is moved to ``<take>.damaged`` (said in
    :attr:`Repaired.damage`). A BVH header gets the number of frames kept. A
    ``<take>.partial`` is then renamed to ``<take>`` unless that exists. The result is read
    back as ``handrig play`` reads it. DataError if the header itself is damaged (nothing
    to keep) or the file cannot be read or written.
    """
    p = Path(path)
    if not p.exists() and partial_path(p).exists():
        p = partial_path(p)
    damage: Damage | None = None
    try:
        with open(p, "r+b") as f:
            size = os.fstat(f.fileno()).st_size
            head = f.read(min(size, _HEAD_MAX))
            glove = head.split(b"\n", 1)[0].strip() == MAGIC.encode()
            layout = glove_layout(head, p) if glove else FORMAT_CLASSES[format_of(p)].layout(
                head, p)
            first_line = head[: layout.data_start].count(b"\n") + 1
            end, frames, bad = _scan(f, layout, first_line)
            if bad is not None:
                line, what = bad
                damage = _move_rest(f, p, end, size, line, what)
            f.truncate(end)
            if layout.count_at >= 0:
                width = layout.count_width
                if width < len(str(frames)):
                    raise DataError(f"{p}: the 'Frames:' field is too narrow for {frames};"
                                    " edit the header by hand")
                f.seek(layout.count_at)
                f.write(f"{frames:<{width}d}".encode("ascii"))
            f.flush()
            os.fsync(f.fileno())
    except FileNotFoundError:
        raise DataError(f"{p}: recording not found") from None
    except IsADirectoryError:
        raise DataError(f"{p}: is a folder, not a take") from None
    except OSError as exc:
        raise DataError(f"{p}: cannot repair: {exc.strerror}") from None
    final = p
    if p.name.endswith(PARTIAL_SUFFIX):
        target = p.with_name(p.name[: -len(PARTIAL_SUFFIX)])
        if not target.exists():
            os.replace(p, target)
            final = target
    if frames:
        _read_back(final, glove)
    return Repaired(final, frames, size - end - (damage.bytes_moved if damage else 0),
                    layout.declared, damage, "glove take" if glove else "performance")


def _read_back(p: Path, glove: bool) -> None:
    """Read the repaired take as ``handrig play`` does: what repair calls sound plays."""
    try:
        if glove:
            read_glove_recording(p)
        else:
            load_performance(p, format_of(p))
    except DataError as exc:
        raise DataError(f"{p}: repaired, but it still does not read ({exc}); keep the file"
                        " and report this") from None


def _scan(f: BinaryIO, layout: FrameLayout, first_line: int
          ) -> tuple[int, int, tuple[int, str] | None]:
    """(the byte after the last sound frame before any damage, the frames up to there,
    the damaged line's number and what is wrong, or None)."""
    f.seek(layout.data_start)
    pos, frames, line = layout.data_start, 0, first_line
    last_t = -math.inf
    while True:
        raw = f.readline(MAX_LINE_BYTES + 1)
        if not raw:
            return pos, frames, None
        if not raw.endswith(b"\n"):
            if _no_newline_after(f):  # the unfinished last line: cut
                return pos, frames, None
            return pos, frames, (line, f"a line longer than {MAX_LINE_BYTES} bytes"
                                 f" (it starts {excerpt(raw)})")
        body = raw.rstrip(b"\r\n")
        if body.strip():
            problem, last_t = _problem(body, layout, last_t)
            if problem:
                return pos, frames, (line, problem)
            frames += 1
        pos += len(raw)
        line += 1


def _no_newline_after(f: BinaryIO) -> bool:
    while True:
        block = f.read(_SCAN_BLOCK)
        if not block:
            return True
        if b"\n" in block:
            return False


def _problem(body: bytes, layout: FrameLayout, last_t: float) -> tuple[str, float]:
    """What is wrong with a frame line ("" when it is sound) and its time."""
    tokens = body.split(layout.sep) if layout.sep is not None else body.split()
    if not layout.good(body):
        if len(tokens) != layout.width:
            n = len(tokens)
            return (f"{n} value{'' if n == 1 else 's'}, the header's frames have"
                    f" {layout.width}", last_t)
        for k, tok in enumerate(tokens):
            try:
                value = float(tok)
            except ValueError:
                if not (layout.sep == b"," and not tok.strip()):  # a glove take's empty cell
                    return f"value {k + 1}, {excerpt(tok.strip(), 24)}, is not a number", last_t
                continue
            if not math.isfinite(value):
                return f"value {k + 1} is {value}", last_t
        return "not a whole frame (" + excerpt(body) + ")", last_t
    if not layout.times:
        return "", last_t
    t = float(tokens[0])
    if t < last_t or (layout.times == "strictly rising" and t == last_t):
        return f"its time {t:g} s does not come after {last_t:g} s", last_t
    return "", t


def glove_layout(head: bytes, p: Path) -> FrameLayout:
    """Where a glove take's frames are (:mod:`handrig.devices.glove_recording`): after the
    first line, the ``#`` lines and the header."""
    lines = head.split(b"\n")
    k = 1
    while k < len(lines) - 1 and lines[k].startswith(b"#"):
        k += 1
    if k >= len(lines) - 1:
        raise DataError(f"{p}: a glove take without its header line (t_s,...,buttons) in the"
                        f" first {len(head)} bytes: cut before its first frame; nothing to keep")
    header = [h.strip() for h in lines[k].decode("utf-8", errors="replace").split(",")]
    if len(header) < 2 or header[0] != "t_s" or header[-1] != "buttons":
        raise DataError(f"{p}: line {k + 1}: a glove take's header must start with t_s and end"
                        f" with buttons, found {excerpt(lines[k])}: the header is damaged;"
                        " nothing to keep")
    width = len(header)
    quat = tuple(header[-5:-1]) == QUAT_COLUMNS
    n_raw = width - (6 if quat else 2)
    data_start = sum(len(ln) + 1 for ln in lines[: k + 1])
    good: Callable[[bytes], bool] = _glove_row_test(width, n_raw, quat)
    return FrameLayout(data_start, good, width=width, sep=b",", times="strictly rising")


def _glove_row_test(width: int, n_raw: int, quat: bool) -> Callable[[bytes], bool]:
    def good(line: bytes) -> bool:
        cells = line.split(b",")
        if len(cells) != width:
            return False
        try:
            numbers = [float(c) for c in cells[: 1 + n_raw]]
            if quat:
                q = cells[-5:-1]
                if any(c.strip() for c in q):
                    numbers += [float(c) for c in q]
            int(cells[-1])
        except ValueError:
            return False
        return all(math.isfinite(v) for v in numbers)

    return good


def _move_rest(f: BinaryIO, p: Path, start: int, size: int, line: int, what: str) -> Damage:
    """Copy ``[start, size)`` of ``f`` to a new ``<take>.damaged`` (never over a file)."""
    name = p.name[: -len(PARTIAL_SUFFIX)] if p.name.endswith(PARTIAL_SUFFIX) else p.name
    k = 1
    while True:
        target = p.with_name(f"{name}{DAMAGED_SUFFIX}" + (f"-{k}" if k > 1 else ""))
        try:
            out = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            k += 1
            continue
        break
    try:
        f.seek(start)
        left = size - start
        while left > 0:
            block = f.read(min(left, _SCAN_BLOCK))
            if not block:
                break
            view = memoryview(block)
            while view:
                view = view[os.write(out, view):]
            left -= len(block)
        os.fsync(out)
    finally:
        os.close(out)
    return Damage(line, start, what, target, size - start)
