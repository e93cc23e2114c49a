"""Performance BVH (for animators): :class:`BvhTake`.

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
``Frame Time`` is ``1 / rate_hz``: frames are evenly spaced and read back
as ``t_s = i * frame_time``; a recording without wrists has zero wrist channels.

BVH needs a fixed frame time while the loop's frames come when the glove's do (and at
the floor rate when it is silent), so :class:`BvhTake` resamples. Frame ``k`` of the
file stands for time ``t_first + k / rate_hz`` and holds the newest frame added at or
before half a frame after that time: a frame within half a frame of it (so a glove at
the file's rate maps one to one, whatever its jitter, instead of a late frame being
doubled and the next dropped), else the frame before it, held, as the servos held
each goal until the next (so a glove silence stays a silence of the same length). The
file covers the frames from the first to the last: it lasts as long as the
performance, within one frame, whatever the glove's rate, catch-up cycles or a
silence.

The header's frame count is a fixed-width field (:data:`FRAMES_WIDTH`), rewritten
after each batch the writer puts in the file.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.config.bounded import excerpt
from handrig.errors import DataError
from handrig.offline.bvh import BvhJoint, format_hierarchy, parse_hierarchy, read_bvh
from handrig.offline.mocap import Profile, load_profile
from handrig.outputs import skeleton
from handrig.outputs.recorder.formats import (
    Emit,
    Format,
    FrameLayout,
    Performance,
    TakeFormat,
    all_numbers,
    check_finite,
)

BVH_PROFILE = "perception_neuron"
"""The joint-mapping profile that puts curves into BVH channels (and takes them out)."""
BVH_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")
FRAMES_FIELD = "Frames: "
"""What precedes the frame count in a BVH header."""
FRAMES_WIDTH = 12
"""Characters of the frame count field a recording reserves (left-aligned, space-padded)."""
GRID_TOLERANCE_S = 1e-7
"""A frame this close to a grid time counts as on it (float rounding of the times)."""
_ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", *BVH_CHANNELS)
_SIDE = {"ri": "Right", "le": "Left"}
_HAND_SPACING_CM = 20.0  # each wrist this far from the root, along the arm (arbitrary)

# wrist DOF -> (joint, channel, sign); see the module docstring
_WRIST_MAP: dict[str, tuple[str, str, float]] = {
    "riWristFlexion": ("RightHand", "Zrotation", 1.0),
    "riWristDeviation": ("RightHand", "Yrotation", 1.0),
    "leWristFlexion": ("LeftHand", "Zrotation", -1.0),
    "leWristDeviation": ("LeftHand", "Yrotation", -1.0),
}

ChannelTable = list[tuple[str, str, float, float]]


class BvhTake(TakeFormat):
    """A performance BVH at ``rate_hz`` frames per second. The channel table is read
    when it is made, so a broken profile fails before the show."""

    name: ClassVar[Format] = "bvh"
    header_needs_wrist: ClassVar[bool] = False

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = float(rate_hz)
        table = bvh_table(load_profile(BVH_PROFILE))
        self._cols, self._sign, self._offset, n_channels = _bvh_layout(table)
        self._motion = np.zeros(n_channels)
        self._tmp = np.zeros(len(table))
        self._line_fmt = b" ".join([b"%.6f"] * n_channels) + b"\n"
        self._frames_at = -1  # byte offset of the 'Frames:' value
        self._held = np.zeros(len(table))  # the newest frame added: what the grid holds
        self._held_line = b""  # its line, once encoded
        self._t0: float | None = None  # the first frame's time: grid time 0
        self._t_last = 0.0
        self._k = 0  # grid frames owed so far

    def header(self, with_wrist: bool) -> bytes:
        head = (format_hierarchy(_bvh_skeleton())
                + f"MOTION\n{FRAMES_FIELD}{frames_value(0)}\n"
                f"Frame Time: {1.0 / self.rate_hz:.10g}\n")
        self._frames_at = head.index(FRAMES_FIELD) + len(FRAMES_FIELD)
        return head.encode("ascii")

    def add(self, t_s: float, values: NDArray[np.float64], with_wrist: bool,
            emit: Emit) -> None:
        t0 = self._t0
        if t0 is None:
            self._t0 = t0 = self._t_last = t_s
        rate, k = self.rate_hz, self._k
        # frame k holds the newest frame at or before t0 + (k + 1/2) / rate: those up
        # to this frame's time hold the frame before it, one just at it holds this one
        before = math.ceil((t_s - GRID_TOLERANCE_S - t0) * rate - 0.5)
        if before > k:
            emit(self._line(), before - k)
            k = before
        np.copyto(self._held, values)
        self._held_line = b""
        self._t_last = max(self._t_last, t_s)
        upto = math.floor((t_s + GRID_TOLERANCE_S - t0) * rate - 0.5) + 1
        if upto > k:
            emit(self._line(), upto - k)
            k = upto
        self._k = k

    def finish(self, emit: Emit) -> None:
        if self._t0 is None:
            return
        # the frames up to the last frame's own time
        total = math.floor((self._t_last + GRID_TOLERANCE_S - self._t0) * self.rate_hz) + 1
        if total > self._k:
            emit(self._line(), total - self._k)
            self._k = total

    def _line(self) -> bytes:
        if not self._held_line:
            tmp = self._tmp
            np.subtract(self._held, self._offset, out=tmp)
            tmp *= self._sign
            m = self._motion
            m[self._cols] = tmp
            self._held_line = self._line_fmt % tuple(m.tolist())
        return self._held_line

    def frames_written(self, fd: int, frames: int) -> None:
        # the header precedes the data, so a killed run's take usually reads as it is
        os.pwrite(fd, frames_value(frames).encode("ascii"), self._frames_at)

    @classmethod
    def load(cls, p: Path) -> Performance:
        bvh = read_bvh(p)
        profile = load_profile(BVH_PROFILE)
        table = bvh_table(profile)
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
        check_finite(values, p, "frame", 0)
        t_s: NDArray[np.float64] = np.arange(bvh.n_frames, dtype=np.float64) * bvh.frame_time_s
        wrist = np.ascontiguousarray(values[:, 50:]) if has_wrist else None
        return t_s, np.ascontiguousarray(values[:, :50]), wrist

    @classmethod
    def layout(cls, head: bytes, p: Path) -> FrameLayout:
        text = head.decode("ascii", errors="replace")
        lines = text.split("\n")
        try:
            m = next(i for i, ln in enumerate(lines) if ln.strip() == "MOTION")
        except StopIteration:
            raise DataError(f"{p}: no MOTION block in the first {len(head)} bytes: the header"
                            " is cut or damaged; nothing to keep") from None
        if m + 2 >= len(lines) or not lines[m + 1].startswith(FRAMES_FIELD.strip()) or (
                not lines[m + 2].startswith("Frame Time:")):
            raise DataError(f"{p}: MOTION is not followed by 'Frames:' and 'Frame Time:'"
                            " lines: the header is cut or damaged; nothing to keep")
        try:
            joints, n_channels = parse_hierarchy(lines[:m], str(p))
        except DataError as exc:
            raise DataError(f"{exc}: the header is damaged; nothing to keep") from None
        names = {j.name for j in joints}
        missing = sorted({j for j, *_ in bvh_table(load_profile(BVH_PROFILE))[:50]
                          if j not in names})
        if missing:
            raise DataError(f"{p}: joint {excerpt(missing[0])} not found in the hierarchy:"
                            " the header is damaged, or not a handrig take; nothing to keep")
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
            return all_numbers(line.split(), n_channels)

        return FrameLayout(data_start, good, value_at, len(field.rstrip("\r")), declared,
                           width=n_channels, sep=None)


def frames_value(n: int) -> str:
    """The header's frame count field for ``n`` frames."""
    return f"{n:<{FRAMES_WIDTH}d}"


def bvh_table(profile: Profile) -> ChannelTable:
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


def _bvh_layout(table: ChannelTable
                ) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64], int]:
    """(motion column, sign, offset_deg) per recorded value, and the channel count."""
    joints = {j.name: j for j in _bvh_skeleton()}
    cols = np.array([joints[j].channel_start + BVH_CHANNELS.index(c) for j, c, _, _ in table],
                    dtype=np.intp)
    sign = np.array([s for _, _, s, _ in table])
    offset = np.array([o for _, _, _, o in table])
    n_channels = len(_ROOT_CHANNELS) + 3 * (len(joints) - 1)
    return cols, sign, offset, n_channels
