"""What every take format shares: :class:`TakeFormat`, the names and the file paths.

A performance is, per frame, a time ``t_s``, the 50 curves of
:data:`handrig.hand.CURVE_NAMES` and optionally the 4 wrist DOFs of
:data:`handrig.outputs.vmc.WRIST_NAMES`, degrees, vocabulary convention. Each format
(:class:`~handrig.outputs.recorder.csv_take.CsvTake`,
:class:`~handrig.outputs.recorder.bvh_take.BvhTake`) knows how to encode a frame, what
its header holds, how to read a file back and where a whole frame ends (for repair).
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar, Literal

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.errors import DataError
from handrig.outputs.vmc import WRIST_NAMES

Format = Literal["csv", "bvh"]
FORMATS: tuple[Format, ...] = ("csv", "bvh")
PARTIAL_SUFFIX = ".partial"
N_VALUES = len(hand.CURVE_NAMES) + len(WRIST_NAMES)
"""Values in a frame: the 50 curves then the 4 wrist DOFs."""

Emit = Callable[[bytes, int], None]
"""Where a format puts its lines: ``emit(line, times)``."""

Performance = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None]
"""(t_s (n,), poses (n, 50), wrist (n, 4) or None)."""


def format_of(path: str | Path, fmt: str | None = None) -> Format:
    """The recording format: ``fmt`` if given, else from the file suffix."""
    p = Path(path)
    if fmt is None and p.name.endswith(PARTIAL_SUFFIX):
        p = p.with_name(p.name[: -len(PARTIAL_SUFFIX)])
    name = fmt if fmt is not None else p.suffix.lower().lstrip(".")
    if name not in FORMATS:
        given = f"format {fmt!r}" if fmt is not None else f"suffix {p.suffix!r}"
        raise DataError(
            f"{path}: unknown recording {given}; use a .csv or .bvh file name"
            " (or fmt='csv'/'bvh')"
        )
    return "csv" if name == "csv" else "bvh"


def partial_path(path: str | Path) -> Path:
    """Where a recording lives until it is closed: ``<path>.partial``."""
    p = Path(path)
    return p.with_name(p.name + PARTIAL_SUFFIX)


def csv_header(with_wrist: bool) -> tuple[str, ...]:
    """Column names of a performance CSV."""
    return ("t_s", *hand.CURVE_NAMES, *(WRIST_NAMES if with_wrist else ()))


@dataclass(frozen=True)
class FrameLayout:
    """Where a file's frames are, for :func:`~handrig.outputs.recorder.repair.repair`:
    the first data byte, a test for a whole frame line, (BVH) the offset and width of
    the header's frame count and the count it holds, and how a line is laid out."""

    data_start: int
    good: Callable[[bytes], bool]
    count_at: int = -1
    count_width: int = 0
    declared: int | None = None
    width: int = 0
    """Values in a frame line."""
    sep: bytes | None = b","
    """What separates them (None: white space)."""
    times: Literal["", "rising", "strictly rising"] = ""
    """The first value is the frame's time: it never goes back ("rising", a performance
    CSV, whose rows may share a time) or always goes forward (a glove take); "": no time
    in the line (BVH)."""


class TakeFormat(ABC):
    """One take format: encodes frames for :class:`~handrig.outputs.recorder.writer.Recorder`,
    reads files back, finds their whole frames for repair."""

    name: ClassVar[Format]
    header_needs_wrist: ClassVar[bool]
    """Whether the header can only be written once it is known if frames carry wrists."""

    @abstractmethod
    def header(self, with_wrist: bool) -> bytes:
        """The bytes before the first frame."""

    @abstractmethod
    def add(self, t_s: float, values: NDArray[np.float64], with_wrist: bool,
            emit: Emit) -> None:
        """A frame at time ``t_s`` (s, never earlier than the one before): ``values`` (54,)
        = 50 curves then 4 wrist DOFs (zeros when the take has none), degrees. Calls
        ``emit(line, times)`` for what is to be written now (a format at a fixed frame
        time writes the frames whose time has come, which may be none or several)."""

    def finish(self, emit: Emit) -> None:  # noqa: B027 - optional hook
        """The end of the take: ``emit`` what is still owed (a format at a fixed frame
        time: the last frame, up to its time)."""

    def frames_written(self, fd: int, frames: int) -> None:  # noqa: B027 - optional hook
        """The writer has put ``frames`` frames in the file ``fd`` (a header that counts
        them is brought up to date here)."""

    @classmethod
    @abstractmethod
    def load(cls, p: Path) -> Performance:
        """Read a take; DataError names the file and the line or frame at fault."""

    @classmethod
    @abstractmethod
    def layout(cls, head: bytes, p: Path) -> FrameLayout:
        """Where the frames of a file starting with ``head`` are (DataError if the header
        is damaged: nothing to keep)."""


def free_path(path: str | Path) -> Path:
    """``path`` if neither it nor its ``.partial`` exists, else the first free
    ``<stem>-2<suffix>``, ``<stem>-3<suffix>`` ... (a take is never replaced)."""
    p = Path(path)
    k = 1
    candidate = p
    while candidate.exists() or partial_path(candidate).exists():
        k += 1
        candidate = p.with_name(f"{p.stem}-{k}{p.suffix}")
    return candidate


def check_new_take(path: str | Path) -> None:
    """DataError, naming the file and the next free name, if ``path`` holds a take already
    (it would be replaced) or its ``.partial`` is there (an unfinished take)."""
    p = Path(path)
    if p.exists():
        raise DataError(
            f"{p}: a take is already there, and a take is never replaced; record to"
            f" {free_path(p)} (the next free name) or move the old take away")
    tmp = partial_path(p)
    if tmp.exists():
        raise DataError(
            f"{tmp}: an unfinished take from a run that did not close it is in"
            f" the way; recover it with `handrig record repair {tmp}` (or move it)"
            " and start again")


def all_numbers(tokens: list[bytes], n: int) -> bool:
    """Whether ``tokens`` are ``n`` finite numbers."""
    if len(tokens) != n:
        return False
    try:
        values = np.array(tokens, dtype=np.float64)
    except ValueError:
        return False
    return bool(np.isfinite(values).all())


def check_finite(values: NDArray[np.float64], p: Path, unit: str, first: int) -> None:
    """DataError naming the first ``unit`` (line, frame) of ``values`` that is not finite."""
    bad = ~np.isfinite(values)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise DataError(f"{p}: {unit} {first + int(r)}: value {values[r, c]} is not finite")


def datasync(fd: int) -> None:
    """Ask the OS to put ``fd``'s data on the disk (fdatasync; fsync where it is missing);
    a pipe or a special file that cannot be synced is fine."""
    import errno

    sync = getattr(os, "fdatasync", os.fsync)  # fdatasync: Linux; fsync elsewhere
    try:
        sync(fd)
    except OSError as exc:
        if exc.errno not in (errno.EINVAL, errno.EROFS):  # a pipe or a special file
            raise
