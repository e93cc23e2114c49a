"""Record a performance (the full pose per frame) as CSV or BVH, read it back, play it back.

A performance is, per frame, a time ``t_s``, the 50 curves of
:data:`handrig.hand.CURVE_NAMES` and optionally the 4 wrist DOFs of
:data:`handrig.outputs.vmc.WRIST_NAMES`, degrees, vocabulary convention.

CSV
    Header row ``t_s,<50 curve names>[,<4 wrist names>]``, one row per frame, values
    with 6 decimals (round trip within 5e-7). Times are the loop's, as recorded.

BVH (for animators)
    A two-hand skeleton in the Perception Neuron layout (Y up, the character faces +Z,
    T-pose with palms down: right-hand bones along -X, left along +X; centimetres):
    ``ROOT Hands`` (6 channels, always zero) with ``RightHand``/``LeftHand`` and under
    each ``<S>HandThumb1..3`` (CMC, MCP, IP) and ``<S>Hand<F>1..3`` (MCP, PIP, DIP)
    for F = Index, Middle, Ring, Pinky; offsets are hand-length fractions
    (REFERENCE.md section 4, :mod:`handrig.outputs.skeleton`). Every joint has
    ``CHANNELS 3 Zrotation Xrotation Yrotation`` (intrinsic ZXY, R = Rz Rx Ry).
    Curves go into channels through the ``perception_neuron`` joint-mapping profile
    (``config/profiles/perception_neuron.toml``) run backwards:
    ``channel = sign * (value - offset_deg)`` (e.g. ``riIndexMCPy`` is the Zrotation
    of ``RightHandIndex1``, sign +1; ``leIndexMCPy`` the Zrotation of
    ``LeftHandIndex1``, sign -1). So the file reads back with the same profile,
    here or with ``handrig.offline.mocap.load_curves(path, "perception_neuron")``, to the same
    curves, and looks in a BVH viewer as the reference capture does. The wrist
    (not in the profile): ``<S>Hand`` Zrotation = flexion and Yrotation = deviation,
    sign +1 on the right and -1 on the left (the skeleton mirrors across X).
    ``Frame Time`` is ``1 / rate_hz``: frames are assumed evenly spaced and read back
    as ``t_s = i * frame_time``; a recording without wrists has zero wrist channels.

:class:`Recorder` streams the take to ``<path>.partial`` while the show runs and
renames it at :meth:`Recorder.close`; :func:`repair` makes a take cut short by a
crash or a power cut readable (every whole frame kept, the BVH frame count set).
"""

from __future__ import annotations

import errno
import math
import os
import sys
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Literal

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.clock import Clock
from handrig.errors import DataError
from handrig.offline.bvh import (
    UNFINISHED_HINT,
    BvhJoint,
    format_hierarchy,
    parse_hierarchy,
    read_bvh,
)
from handrig.offline.mocap import Profile, load_profile
from handrig.outputs import skeleton
from handrig.outputs.vmc import WRIST_NAMES

Format = Literal["csv", "bvh"]
FORMATS: tuple[Format, ...] = ("csv", "bvh")
PARTIAL_SUFFIX = ".partial"
_IOV_MAX = 1024 if sys.platform.startswith("linux") else 16  # buffers per writev (Linux; POSIX)
BVH_PROFILE = "perception_neuron"
"""The joint-mapping profile that puts curves into BVH channels (and takes them out)."""
BVH_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")
_ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", *BVH_CHANNELS)
_SIDE = {"ri": "Right", "le": "Left"}
_HAND_SPACING_CM = 20.0  # each wrist this far from the root, along the arm (arbitrary)
_N = 1 + len(hand.CURVE_NAMES) + len(WRIST_NAMES)  # columns of a buffered frame

# wrist DOF -> (joint, channel, sign); see the module docstring
_WRIST_MAP: dict[str, tuple[str, str, float]] = {
    "riWristFlexion": ("RightHand", "Zrotation", 1.0),
    "riWristDeviation": ("RightHand", "Yrotation", 1.0),
    "leWristFlexion": ("LeftHand", "Zrotation", -1.0),
    "leWristDeviation": ("LeftHand", "Yrotation", -1.0),
}


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


class Recorder:
    """Stream frames to a CSV or BVH file while the show runs.

    ``add`` (or calling the recorder, the rig's output hook) turns the frame into one
    text line at once and appends it to a list; a writer thread takes that list every
    ``flush_s`` seconds, writes it with ``os.writev`` and (``sync=True``) asks the OS to
    put it on the disk (``fdatasync``). So a killed process or a power cut loses at most
    the last ``flush_s`` seconds plus one write, and memory holds at most
    ``max_pending_s`` seconds of lines (frames beyond that, when the disk stalls, are
    dropped and counted in :attr:`frames_dropped`, never raised into the loop). A
    write error (disk full) stops the writing, is kept in :attr:`error` and raised by
    :meth:`close`, which then leaves the take as ``<path>.partial`` for :func:`repair`.

    The file is written as ``<path>.partial`` and renamed to ``path`` by :meth:`close`.
    The BVH header's frame count is a fixed-width field, rewritten after each batch, so
    a take cut by a kill between batches reads as it is; one cut inside a batch or by a
    power cut needs :func:`repair`. A ``.partial`` left by a run that did not close is
    refused at start (it holds a take): :func:`repair` turns it into a readable file.
    ``with_wrist``: record the 4 wrist DOFs; None decides on the first frame.
    """

    def __init__(self, path: str | Path, fmt: str | None = None, rate_hz: float = 200.0, *,
                 with_wrist: bool | None = None, flush_s: float = 0.5, sync: bool = True,
                 max_pending_s: float = 60.0) -> None:
        self.path = Path(path)
        self.fmt: Format = format_of(self.path, fmt)
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise DataError(f"{self.path}: rate_hz must be a positive number, got {rate_hz}")
        if not (math.isfinite(flush_s) and 0 < flush_s <= 1.0):
            raise ValueError(f"flush_s must be in (0, 1] s, got {flush_s}")
        if not (math.isfinite(max_pending_s) and max_pending_s >= flush_s):
            raise ValueError(f"max_pending_s must be at least flush_s, got {max_pending_s}")
        self.rate_hz = float(rate_hz)
        self.with_wrist = with_wrist
        self.flush_s = float(flush_s)
        self.sync = sync
        self._max_pending = max(1, math.ceil(max_pending_s * self.rate_hz)) + 1  # + header
        self._n_added = 0
        self.frames_dropped = 0
        """Frames not recorded because the disk fell ``max_pending_s`` behind or failed."""
        self.frames_written = 0
        """Frames the writer has handed to the OS (and synced, with ``sync``)."""
        self.bytes_written = 0
        self.error: DataError | None = None
        self._closed = False
        self._pending: list[bytes] = []
        self._lock = threading.Lock()  # the pending list (the loop thread takes only this)
        self._io_lock = threading.Lock()  # the file
        self._wake = threading.Event()
        self._stop = False
        self._frames_offset = -1  # byte offset of the BVH 'Frames:' value
        # the channel table is read now, so a broken profile fails before the show
        self._table = _bvh_table(load_profile(BVH_PROFILE)) if self.fmt == "bvh" else []
        self._row = np.zeros(_N - 1)
        self._tmp_row = np.zeros(_N - 1)
        if self.fmt == "bvh":
            self._cols, self._sign, self._offset, n_channels = _bvh_layout(self._table)
            self._motion = np.zeros(n_channels)
            self._line_fmt = b" ".join([b"%.6f"] * n_channels) + b"\n"
        self._tmp = partial_path(self.path)
        if self._tmp.exists():
            raise DataError(
                f"{self._tmp}: an unfinished take from a run that did not close it is in"
                f" the way; recover it with `handrig record repair {self._tmp}` (or move it)"
                " and start again")
        try:
            self._fd = os.open(self._tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except OSError as exc:
            raise DataError(
                f"{self.path}: cannot create the recording ({exc.strerror}); check that the"
                " directory exists and is writable"
            ) from None
        if self.fmt == "csv" and self.with_wrist is not None:
            self._start_csv()
        if self.fmt == "bvh":
            head = _bvh_header(self.rate_hz)
            self._frames_offset = head.index(FRAMES_FIELD) + len(FRAMES_FIELD)
            self._pending.append(head.encode("ascii"))
        self._thread = threading.Thread(target=self._writer, name=f"recorder:{self.path.name}",
                                        daemon=True)
        self._thread.start()

    @property
    def n_frames(self) -> int:
        """Frames added so far (recorded or, see :attr:`frames_dropped`, dropped)."""
        return self._n_added

    def add(self, t_s: float, pose50_deg: NDArray[np.float64],
            wrist_deg: NDArray[np.float64] | None = None) -> None:
        """Append one frame: time (s), (50,) curves and (4,) wrist DOFs or None (degrees)."""
        if self._closed:
            raise ValueError(f"{self.path}: the recording is closed")
        if self.with_wrist is None:
            self.with_wrist = wrist_deg is not None
            if self.fmt == "csv":
                self._start_csv()
        if wrist_deg is None and self.with_wrist:
            raise ValueError(f"{self.path}: this recording has wrist DOFs; pass wrist_deg")
        row = self._row
        row[:50] = pose50_deg
        if wrist_deg is not None:
            row[50:] = wrist_deg
        if self.fmt == "csv":
            values = row if self.with_wrist else row[:50]
            line = self._line_fmt % (t_s, *values.tolist())
        else:
            if wrist_deg is None:
                row[50:] = 0.0
            tmp = self._tmp_row
            np.subtract(row, self._offset, out=tmp)
            tmp *= self._sign
            m = self._motion
            m[self._cols] = tmp
            line = self._line_fmt % tuple(m.tolist())
        self._n_added += 1
        with self._lock:
            if len(self._pending) >= self._max_pending or self.error is not None:
                self.frames_dropped += 1
                return
            self._pending.append(line)

    def _start_csv(self) -> None:
        names = csv_header(bool(self.with_wrist))
        self._line_fmt = b",".join([b"%.6f"] * len(names)) + b"\n"
        with self._lock:
            self._pending.append((",".join(names) + "\n").encode("ascii"))

    def __call__(self, t_s: float, pose54_deg: NDArray[np.float64]) -> None:
        """The rig's output hook: ``pose54_deg`` = 50 curves then the 4 wrist DOFs
        (:data:`handrig.hand.ALL_JOINT_NAMES` order)."""
        self.add(t_s, pose54_deg[:50], pose54_deg[50:54])

    def _writer(self) -> None:
        while True:
            self._wake.wait(self.flush_s)
            self._wake.clear()
            stop = self._stop
            self._write_pending()
            if stop:
                return

    def _write_pending(self) -> None:
        with self._io_lock:  # batches reach the file in the order they were taken
            with self._lock:
                lines, self._pending = self._pending, []
            if lines and self.error is None:
                self._write(lines)

    def _write(self, lines: list[bytes]) -> None:
        header = 1 if self.bytes_written == 0 else 0  # the first line written is the header
        size = 0
        try:
            for k in range(0, len(lines), _IOV_MAX):  # no join: writev releases the GIL
                group = lines[k: k + _IOV_MAX]
                want = sum(len(b) for b in group)
                done = os.writev(self._fd, group)
                if done < want:  # a short write (a signal, a full disk): write the rest
                    view = memoryview(b"".join(group))[done:]
                    while view:
                        view = view[os.write(self._fd, view):]
                size += want
            if self.sync:
                _datasync(self._fd)
        except OSError as exc:
            with self._lock:
                self.error = DataError(
                    f"{self.path}: writing the recording failed ({exc.strerror}); the take"
                    f" holds the first {self.frames_written} frames")
                self.frames_dropped += len(lines) - header
            return
        self.bytes_written += size
        self.frames_written += len(lines) - header
        if self.fmt == "bvh":
            # the header follows the data, so a killed run's take usually reads as it is
            try:
                os.pwrite(self._fd, _frames_value(self.frames_written).encode("ascii"),
                          self._frames_offset)
            except OSError as exc:
                with self._lock:
                    self.error = DataError(f"{self.path}: updating the frame count failed"
                                           f" ({exc.strerror})")

    def flush(self) -> None:
        """Write everything added so far now (from the calling thread)."""
        self._write_pending()

    def close(self) -> Path:
        """Write the rest, set the BVH frame count, rename to the final name (once)."""
        if self._closed:
            return self.path
        self._closed = True
        if self.fmt == "csv" and self.with_wrist is None:
            self.with_wrist = False
            self._start_csv()
        self._stop = True
        self._wake.set()
        self._thread.join()
        if self.error is not None:  # the take stays a .partial, for repair
            os.close(self._fd)
            raise DataError(f"{self.error}; what was written is in {self._tmp}: `handrig"
                            f" record repair {self._tmp}` keeps its whole frames")
        try:
            if self.fmt == "bvh":
                os.pwrite(self._fd, _frames_value(self.frames_written).encode("ascii"),
                          self._frames_offset)
                _datasync(self._fd)
            os.close(self._fd)
            os.replace(self._tmp, self.path)
        except OSError as exc:
            raise DataError(f"{self.path}: finishing the recording failed ({exc.strerror});"
                            f" the take is in {self._tmp}: `handrig record repair"
                            f" {self._tmp}` makes it readable") from None
        return self.path

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def csv_header(with_wrist: bool) -> tuple[str, ...]:
    """Column names of a performance CSV."""
    return ("t_s", *hand.CURVE_NAMES, *(WRIST_NAMES if with_wrist else ()))


def _bvh_table(profile: Profile) -> list[tuple[str, str, float, float]]:
    """(joint, channel, sign, offset_deg) for the 50 curves then the 4 wrist DOFs."""
    return [*profile.resolve(), *((j, c, s, 0.0) for j, c, s in _WRIST_MAP.values())]


def _bvh_joints() -> list[tuple[str, int, tuple[float, float, float], tuple[float, float, float]]]:
    """(name, parent index, offset cm, end-site offset cm or zeros) in file order."""
    out: list[tuple[str, int, tuple[float, float, float], tuple[float, float, float]]] = [
        ("Hands", -1, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    ]
    cm = 100.0
    for side in hand.HANDS:
        sx = -1.0 if side == "ri" else 1.0  # the arm's outward direction is -X on the right

        def pn(v: skeleton.Anat, sx: float = sx) -> tuple[float, float, float]:
            return (sx * v.out * cm, v.up * cm, v.fwd * cm)

        hand_index = len(out)
        out.append((f"{_SIDE[side]}Hand", 0, (sx * _HAND_SPACING_CM, 0.0, 0.0), (0.0,) * 3))
        for digit in hand.DIGITS:
            root, a, b, tip = skeleton.digit_offsets_m(digit)
            # digit bones lie along the arm in the reference skeleton's rest pose
            a, b, tip = (skeleton.Anat(v.norm(), 0.0, 0.0) for v in (a, b, tip))
            parent = hand_index
            for k, off in enumerate((root, a, b), start=1):
                end = pn(tip) if k == 3 else (0.0, 0.0, 0.0)
                out.append((f"{_SIDE[side]}Hand{digit}{k}", parent, pn(off), end))
                parent = len(out) - 1
    return out


def _bvh_skeleton() -> tuple[BvhJoint, ...]:
    """The recording's joints: the root's 6 channels, then 3 rotations per joint."""
    joints = _bvh_joints()
    out = []
    for i, (name, parent, off, end) in enumerate(joints):
        start = 0 if i == 0 else len(_ROOT_CHANNELS) + 3 * (i - 1)
        out.append(BvhJoint(name, parent, off, _ROOT_CHANNELS if parent < 0 else BVH_CHANNELS,
                            start, end))
    return tuple(out)


def _bvh_layout(table: list[tuple[str, str, float, float]]
                ) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64], int]:
    """(motion column, sign, offset_deg) per recorded value, and the channel count."""
    joints = {j.name: j for j in _bvh_skeleton()}
    cols = np.array([joints[j].channel_start + BVH_CHANNELS.index(c) for j, c, _, _ in table],
                    dtype=np.intp)
    sign = np.array([s for _, _, s, _ in table])
    offset = np.array([o for _, _, _, o in table])
    n_channels = len(_ROOT_CHANNELS) + 3 * (len(joints) - 1)
    return cols, sign, offset, n_channels


FRAMES_FIELD = "Frames: "
"""What precedes the frame count in a BVH header."""
FRAMES_WIDTH = 12
"""Characters of the frame count field a recording reserves (left-aligned, space-padded)."""


def _frames_value(n: int) -> str:
    return f"{n:<{FRAMES_WIDTH}d}"


def _bvh_header(rate_hz: float) -> str:
    return (format_hierarchy(_bvh_skeleton()) + f"MOTION\n{FRAMES_FIELD}{_frames_value(0)}\n"
            f"Frame Time: {1.0 / rate_hz:.10g}\n")


def _datasync(fd: int) -> None:
    sync = getattr(os, "fdatasync", os.fsync)  # fdatasync: Linux; fsync elsewhere
    try:
        sync(fd)
    except OSError as exc:
        if exc.errno not in (errno.EINVAL, errno.EROFS):  # a pipe or a special file
            raise


def partial_path(path: str | Path) -> Path:
    """Where a recording lives until it is closed: ``<path>.partial``."""
    p = Path(path)
    return p.with_name(p.name + PARTIAL_SUFFIX)


Performance = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None]


def load_performance(path: str | Path, fmt: str | None = None) -> Performance:
    """Read a recorded performance: (t_s (n,), poses (n, 50), wrist (n, 4) or None).

    CSV: the columns are found by name (any order; the wrist columns all or none);
    BVH: any file whose skeleton has the ``perception_neuron`` profile's joints (this
    module's recordings, Perception Neuron captures); wrist DOFs when ``RightHand``
    and ``LeftHand`` carry rotation channels. DataError names the file and the line
    (CSV) or frame (BVH) of anything malformed or truncated.
    """
    p = Path(path)
    kind = format_of(p, fmt)
    if not p.exists():
        raise DataError(f"{p}: recording not found")
    return _load_csv(p) if kind == "csv" else _load_bvh(p)


def _load_bvh(p: Path) -> Performance:
    bvh = read_bvh(p)
    profile = load_profile(BVH_PROFILE)
    table = _bvh_table(profile)
    names = set(bvh.joint_names)
    missing = sorted({j for j, *_ in table[:50] if j not in names})
    if missing:
        raise DataError(
            f"{p}: joint {missing[0]!r} not found ({len(missing)} of the"
            f" {profile.name!r} profile's joints missing): not a handrig recording or a"
            " Perception Neuron hand capture"
        )
    has_wrist = all(
        j in names and c in bvh.joint(j).channels for j, c, _, _ in table[50:]
    )
    use = table if has_wrist else table[:50]
    cols = np.array([bvh.column(j, c) for j, c, _, _ in use], dtype=np.intp)
    sign = np.array([s for _, _, s, _ in use])
    offset = np.array([o for _, _, _, o in use])
    values: NDArray[np.float64] = bvh.motion[:, cols] * sign + offset
    _check_finite(values, p, "frame", 0)
    t_s: NDArray[np.float64] = np.arange(bvh.n_frames, dtype=np.float64) * bvh.frame_time_s
    wrist = np.ascontiguousarray(values[:, 50:]) if has_wrist else None
    return t_s, np.ascontiguousarray(values[:, :50]), wrist


def _check_finite(values: NDArray[np.float64], p: Path, unit: str, first: int) -> None:
    bad = ~np.isfinite(values)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise DataError(f"{p}: {unit} {first + int(r)}: value {values[r, c]} is not finite")


def _load_csv(p: Path) -> Performance:
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{p}: cannot read the recording: {exc}") from None
    lines = text.splitlines()
    if not lines:
        raise DataError(f"{p}: empty file: expected a header row 't_s,<curve names>'")
    header = [h.strip() for h in lines[0].split(",")]
    if header[0] != "t_s":
        raise DataError(f"{p}: line 1: the first column must be 't_s', found {header[0]!r};"
                        " not a handrig performance CSV")
    unknown = [h for h in header[1:] if h not in hand.CURVE_NAMES and h not in WRIST_NAMES]
    if unknown:
        raise DataError(f"{p}: line 1: unknown column {unknown[0]!r}"
                        f" (columns are t_s, the 50 curve names and optionally {WRIST_NAMES})")
    missing = [n for n in hand.CURVE_NAMES if n not in header]
    if missing:
        raise DataError(f"{p}: line 1: {len(missing)} curve column(s) missing,"
                        f" first {missing[0]!r}")
    if len(set(header)) != len(header):
        dup = next(h for h in header if header.count(h) > 1)
        raise DataError(f"{p}: line 1: column {dup!r} appears twice")
    wrist_cols = [n for n in WRIST_NAMES if n in header]
    if wrist_cols and len(wrist_cols) != len(WRIST_NAMES):
        raise DataError(f"{p}: line 1: wrist columns must be all of {WRIST_NAMES} or none;"
                        f" found {wrist_cols}")
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
    _check_finite(data, p, "line", rows[0][0])
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


_SCAN_BLOCK = 1 << 20
_HEAD_MAX = 1 << 20  # a BVH hierarchy is a few kilobytes


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
    kind = format_of(p)
    try:
        with open(p, "r+b") as f:
            size = os.fstat(f.fileno()).st_size
            head = f.read(min(size, _HEAD_MAX))
            if kind == "bvh":
                data_start, good, frames_at, width, declared = _bvh_parts(head, p)
            else:
                data_start, good, frames_at, width, declared = _csv_parts(head, p)
            end = _last_good_end(f, data_start, size, good)
            frames = _count_lines(f, data_start, end)
            f.truncate(end)
            if kind == "bvh":
                value = f"{frames:<{width}d}" if width >= len(str(frames)) else None
                if value is None:
                    raise DataError(f"{p}: the 'Frames:' field is too narrow for {frames};"
                                    " edit the header by hand")
                f.seek(frames_at)
                f.write(value.encode("ascii"))
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
    return Repaired(final, frames, size - end, declared)


def _bvh_parts(head: bytes, p: Path
               ) -> tuple[int, Callable[[bytes], bool], int, int, int | None]:
    """(first data byte, whole-frame test, offset and width of the Frames value, its value)."""
    text = head.decode("ascii", errors="replace")
    lines = text.split("\n")
    try:
        m = next(i for i, ln in enumerate(lines) if ln.strip() == "MOTION")
    except StopIteration:
        raise DataError(f"{p}: no MOTION block in the first {len(head)} bytes: the header is"
                        " cut or damaged; nothing to keep") from None
    if m + 2 >= len(lines) or not lines[m + 1].startswith(FRAMES_FIELD.strip()) or (
            not lines[m + 2].startswith("Frame Time:")):
        raise DataError(f"{p}: MOTION is not followed by 'Frames:' and 'Frame Time:' lines:"
                        " the header is cut or damaged; nothing to keep")
    _, n_channels = parse_hierarchy(lines[:m], str(p))
    frames_line_at = sum(len(ln) + 1 for ln in lines[: m + 1])
    field = lines[m + 1].split(":", 1)[1]
    value_at = frames_line_at + len(lines[m + 1]) - len(field)
    declared: int | None
    try:
        declared = int(field)
    except ValueError:
        declared = None
    if field.startswith(" "):  # keep 'Frames: ' readable: the number after the space
        value_at += 1
        field = field[1:]
    data_start = frames_line_at + len(lines[m + 1]) + 1 + len(lines[m + 2]) + 1

    def good(line: bytes) -> bool:
        return _numbers(line.split(), n_channels)

    return data_start, good, value_at, len(field.rstrip("\r")), declared


def _csv_parts(head: bytes, p: Path
               ) -> tuple[int, Callable[[bytes], bool], int, int, int | None]:
    nl = head.find(b"\n")
    first = head[: nl if nl >= 0 else len(head)].decode("ascii", errors="replace")
    if nl < 0 or not first.startswith("t_s,"):
        raise DataError(f"{p}: no header row 't_s,<curve names>': not a handrig performance"
                        " CSV, or cut before its first frame; nothing to keep")
    width = len(first.split(","))

    def good(line: bytes) -> bool:
        return _numbers(line.split(b","), width)

    return nl + 1, good, -1, 0, None


def _numbers(tokens: list[bytes], n: int) -> bool:
    if len(tokens) != n:
        return False
    try:
        values = np.array(tokens, dtype=np.float64)
    except ValueError:
        return False
    return bool(np.isfinite(values).all())


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


class Playback:
    """Play a recorded performance back on ``clock`` at its recorded times.

    Two ways to use it: iterate (``for t_s, pose, wrist in playback``), which sleeps on
    the clock until each frame is due; or, from a fixed-rate loop, call :meth:`start`
    once and :meth:`sample` every tick, which never blocks and returns the latest frame
    due. ``speed`` scales time (2.0 plays twice as fast); ``loop`` starts over at the end.
    ``wrist`` is None when the recording has no wrist DOFs.
    """

    def __init__(self, path: str | Path, clock: Clock, *, speed: float = 1.0,
                 loop: bool = False) -> None:
        if not (math.isfinite(speed) and speed > 0):
            raise DataError(f"{path}: playback speed must be positive, got {speed}")
        self.path = Path(path)
        self.t_s, self.poses, self.wrist = load_performance(self.path)
        self.clock = clock
        self.speed = float(speed)
        self.loop = loop
        self._rel_s = self.t_s - self.t_s[0]
        period = float(np.median(np.diff(self._rel_s))) if len(self._rel_s) > 1 else 0.0
        self.duration_s = float(self._rel_s[-1]) + period
        self._start_s = 0.0

    @property
    def n_frames(self) -> int:
        return int(self.t_s.shape[0])

    def start(self) -> None:
        """Start the performance now (on the clock)."""
        self._start_s = self.clock.now()

    def elapsed_s(self) -> float:
        """Performance time since :meth:`start` (scaled by ``speed``), seconds."""
        return (self.clock.now() - self._start_s) * self.speed

    def index_at(self, now_s: float) -> int | None:
        """Index of the frame due at clock time ``now_s``; None after the end (no loop)."""
        rel = (now_s - self._start_s) * self.speed
        if self.loop and self.duration_s > 0:
            rel %= self.duration_s
        elif rel > self.duration_s:
            return None
        return max(int(np.searchsorted(self._rel_s, rel, side="right")) - 1, 0)

    def sample(self) -> tuple[NDArray[np.float64], NDArray[np.float64] | None] | None:
        """(pose (50,), wrist (4,) or None) due now, or None once it has ended."""
        i = self.index_at(self.clock.now())
        if i is None:
            return None
        return self.poses[i], (self.wrist[i] if self.wrist is not None else None)

    def __iter__(self) -> Iterator[tuple[float, NDArray[np.float64], NDArray[np.float64] | None]]:
        self.start()
        while True:
            for i in range(self.n_frames):
                self.clock.sleep_until(self._start_s + self._rel_s[i] / self.speed)
                yield float(self.t_s[i]), self.poses[i], (
                    self.wrist[i] if self.wrist is not None else None)
            if not self.loop:
                return
            self._start_s += self.duration_s / self.speed
