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
    here or with ``handrig.mocap.load_curves(path, "perception_neuron")``, to the same
    curves, and looks in a BVH viewer as the reference capture does. The wrist
    (not in the profile): ``<S>Hand`` Zrotation = flexion and Yrotation = deviation,
    sign +1 on the right and -1 on the left (the skeleton mirrors across X).
    ``Frame Time`` is ``1 / rate_hz``: frames are assumed evenly spaced and read back
    as ``t_s = i * frame_time``; a recording without wrists has zero wrist channels.

:class:`Recorder` keeps frames in preallocated numpy chunks; nothing touches the disk
until :meth:`Recorder.close` (the file is created up front so a bad path fails before
the show, and written through a temporary name then renamed, so a crash never leaves
half a file under the final name).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Literal, TextIO

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.bvh import Bvh, BvhJoint, read_bvh, write_bvh
from handrig.clock import Clock
from handrig.errors import DataError
from handrig.mocap import Profile, load_profile
from handrig.outputs import skeleton
from handrig.outputs.vmc import WRIST_NAMES

Format = Literal["csv", "bvh"]
FORMATS: tuple[Format, ...] = ("csv", "bvh")
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
    name = fmt if fmt is not None else Path(path).suffix.lower().lstrip(".")
    if name not in FORMATS:
        given = f"format {fmt!r}" if fmt is not None else f"suffix {Path(path).suffix!r}"
        raise DataError(
            f"{path}: unknown recording {given}; use a .csv or .bvh file name"
            " (or fmt='csv'/'bvh')"
        )
    return "csv" if name == "csv" else "bvh"


class Recorder:
    """Collect frames in memory and write them as CSV or BVH on :meth:`close`.

    ``add`` costs a row copy into a preallocated chunk (``chunk_frames`` rows, float64);
    a full chunk is kept and a new one allocated. Memory is 440 bytes per frame (5.3 MB
    per minute at 200 Hz, 320 MB per hour). ``with_wrist``: record the 4 wrist DOFs;
    None decides on the first frame. Use as a context manager or call ``close`` in a
    ``finally``: frames not yet closed are lost if the process dies.
    """

    def __init__(self, path: str | Path, fmt: str | None = None, rate_hz: float = 200.0, *,
                 with_wrist: bool | None = None, chunk_frames: int = 4096) -> None:
        self.path = Path(path)
        self.fmt: Format = format_of(self.path, fmt)
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise DataError(f"{self.path}: rate_hz must be a positive number, got {rate_hz}")
        self.rate_hz = float(rate_hz)
        self.with_wrist = with_wrist
        if chunk_frames < 1:
            raise ValueError(f"chunk_frames must be >= 1, got {chunk_frames}")
        self._chunk_frames = int(chunk_frames)
        self._chunks: list[NDArray[np.float64]] = []
        self._chunk = np.empty((self._chunk_frames, _N))
        self._i = 0
        self._closed = False
        # the channel table is read now, so a broken profile fails before the show
        self._table = _bvh_table(load_profile(BVH_PROFILE)) if self.fmt == "bvh" else []
        self._tmp = self.path.with_name(self.path.name + ".partial")
        try:
            self._file = open(self._tmp, "w", encoding="ascii", newline="\n")  # noqa: SIM115
        except OSError as exc:
            raise DataError(
                f"{self.path}: cannot create the recording ({exc.strerror}); check that the"
                " directory exists and is writable"
            ) from None

    @property
    def n_frames(self) -> int:
        """Frames added so far."""
        return len(self._chunks) * self._chunk_frames + self._i

    def add(self, t_s: float, pose50_deg: NDArray[np.float64],
            wrist_deg: NDArray[np.float64] | None = None) -> None:
        """Append one frame: time (s), (50,) curves and (4,) wrist DOFs or None (degrees)."""
        if self._closed:
            raise ValueError(f"{self.path}: the recording is closed")
        if self.with_wrist is None:
            self.with_wrist = wrist_deg is not None
        row = self._chunk[self._i]
        row[0] = t_s
        row[1:51] = pose50_deg
        if wrist_deg is not None:
            row[51:] = wrist_deg
        elif self.with_wrist:
            raise ValueError(f"{self.path}: this recording has wrist DOFs; pass wrist_deg")
        self._i += 1
        if self._i == self._chunk_frames:
            self._chunks.append(self._chunk)
            self._chunk = np.empty((self._chunk_frames, _N))
            self._i = 0

    def __call__(self, t_s: float, pose54_deg: NDArray[np.float64]) -> None:
        """The rig's output hook: ``pose54_deg`` = 50 curves then the 4 wrist DOFs
        (:data:`handrig.hand.ALL_JOINT_NAMES` order)."""
        self.add(t_s, pose54_deg[:50], pose54_deg[50:54])

    def frames(self) -> NDArray[np.float64]:
        """All frames so far, (n, 55): t_s, 50 curves, 4 wrist DOFs (undefined if none)."""
        return np.concatenate([*self._chunks, self._chunk[: self._i]])

    def close(self) -> Path:
        """Write the file (once) and return its path."""
        if self._closed:
            return self.path
        self._closed = True
        data = self.frames()
        try:
            with self._file as f:
                if self.fmt == "csv":
                    _write_csv(f, data, bool(self.with_wrist))
                else:
                    _write_bvh(f, data, self.rate_hz, bool(self.with_wrist), self._table)
            os.replace(self._tmp, self.path)
        except OSError as exc:
            raise DataError(f"{self.path}: writing the recording failed: {exc}") from None
        return self.path

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def csv_header(with_wrist: bool) -> tuple[str, ...]:
    """Column names of a performance CSV."""
    return ("t_s", *hand.CURVE_NAMES, *(WRIST_NAMES if with_wrist else ()))


def _write_csv(f: TextIO, data: NDArray[np.float64], with_wrist: bool) -> None:
    cols = data if with_wrist else data[:, :51]
    np.savetxt(f, cols, fmt="%.6f", delimiter=",", header=",".join(csv_header(with_wrist)),
               comments="")


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


def _write_bvh(f: TextIO, data: NDArray[np.float64], rate_hz: float, with_wrist: bool,
               table: list[tuple[str, str, float, float]]) -> None:
    joints = _bvh_joints()
    names = [j[0] for j in joints]
    start = {name: len(_ROOT_CHANNELS) + 3 * (i - 1) for i, name in enumerate(names) if i}
    bvh_joints = tuple(
        BvhJoint(name, parent, off, _ROOT_CHANNELS if parent < 0 else BVH_CHANNELS,
                 0 if parent < 0 else start[name], end)
        for name, parent, off, end in joints
    )
    n = data.shape[0]
    motion = np.zeros((n, len(_ROOT_CHANNELS) + 3 * (len(names) - 1)))
    values = data[:, 1:] if with_wrist else np.concatenate(
        [data[:, 1:51], np.zeros((n, len(WRIST_NAMES)))], axis=1)
    for k, (joint, channel, sign, offset) in enumerate(table):
        motion[:, start[joint] + BVH_CHANNELS.index(channel)] = sign * (values[:, k] - offset)
    write_bvh(f, Bvh(bvh_joints, 1.0 / rate_hz, motion), decimals=6)


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
            last = " (the last line: the file is truncated)" if n == rows[-1][0] else ""
            raise DataError(f"{p}: line {n}: {len(fields)} values, expected {width}{last}")
        for col, tok in enumerate(fields):
            try:
                float(tok)
            except ValueError:
                raise DataError(f"{p}: line {n}, column {col + 1}: {tok.strip()!r} is not"
                                " a number") from None


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
