"""Make a take cut short by a crash or a power cut readable: :func:`repair`."""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from handrig.errors import DataError
from handrig.outputs.recorder.formats import PARTIAL_SUFFIX, format_of, partial_path
from handrig.outputs.recorder.loading import FORMAT_CLASSES

_SCAN_BLOCK = 1 << 20
_HEAD_MAX = 1 << 20  # a BVH hierarchy is a few kilobytes


@dataclass(frozen=True)
class Repaired:
    """What :func:`repair` did: the readable file, its frames, and what it cut off."""

    path: Path
    frames: int
    bytes_dropped: int
    declared_frames: int | None
    """The frame count the BVH header held before (None for CSV)."""

    def describe(self) -> str:
        cut = (f"cut {self.bytes_dropped} bytes of an unfinished frame" if self.bytes_dropped
               else "nothing cut")
        was = ("" if self.declared_frames is None or self.declared_frames == self.frames
               else f", the header said {self.declared_frames}")
        return f"{self.path}: {self.frames} whole frames ({cut}{was})"


def repair(path: str | Path) -> Repaired:
    """Make a recording cut short by a crash readable, in place, streaming (any length).

    Everything after the last whole frame (a cut line, the zeros a power cut can leave)
    is truncated; a BVH header gets the number of frames kept. A ``<take>.partial`` is
    then renamed to ``<take>`` unless that exists. DataError if the header itself is
    damaged (nothing to keep) or the file cannot be read or written.
    """
    p = Path(path)
    if not p.exists() and partial_path(p).exists():
        p = partial_path(p)
    kind = FORMAT_CLASSES[format_of(p)]
    try:
        with open(p, "r+b") as f:
            size = os.fstat(f.fileno()).st_size
            head = f.read(min(size, _HEAD_MAX))
            layout = kind.layout(head, p)
            end = _last_good_end(f, layout.data_start, size, layout.good)
            frames = _count_lines(f, layout.data_start, end)
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
    except OSError as exc:
        raise DataError(f"{p}: cannot repair: {exc.strerror}") from None
    final = p
    if p.name.endswith(PARTIAL_SUFFIX):
        target = p.with_name(p.name[: -len(PARTIAL_SUFFIX)])
        if not target.exists():
            os.replace(p, target)
            final = target
    return Repaired(final, frames, size - end, layout.declared)


def _last_good_end(f: BinaryIO, start: int, size: int, good: Callable[[bytes], bool]) -> int:
    """The byte after the last line in ``[start, size)`` that ends in a newline and is good."""
    pos = size
    while pos > start:
        lo = max(start, pos - _SCAN_BLOCK)
        f.seek(lo)
        block = f.read(pos - lo)
        nl = block.rfind(b"\n")
        next_pos = lo
        while nl >= 0:
            prev = block.rfind(b"\n", 0, nl)
            if prev < 0 and lo > start:  # the line begins before this block
                next_pos = lo + nl + 1 if nl + 1 < _SCAN_BLOCK // 2 else lo
                break
            if good(block[prev + 1: nl]):
                return lo + nl + 1
            nl = prev
        pos = next_pos
    return start


def _count_lines(f: BinaryIO, start: int, end: int) -> int:
    f.seek(start)
    n, left = 0, end - start
    while left > 0:
        block = f.read(min(left, 8 * _SCAN_BLOCK))
        if not block:
            break
        n += block.count(b"\n")
        left -= len(block)
    return n
