"""A scripted glove calibration: the poses ``handrig calibrate glove`` asks for, as raw counts.

An emulated glove whose sensors read ``open_raw`` with the hand open and
``closed_raw`` at each sensor's full closing (:class:`ScriptedSensors`) goes
through the calibration's poses in its order (open hand, fist, thumb to little
finger, thumb spread). Each pose is a fraction of the way from open to closed
per control curve (:data:`POSE_FRACTIONS`): every flexion sensor closes fully in
exactly one pose (the fingers in the fist, the thumb's twist and flexion when it
touches the little finger, its adduction in the fist), and the spread takes the
thumb's abduction past the open reading. A calibration of this glove should then
find ``raw_open = open_raw`` and ``raw_closed = closed_raw`` for every channel,
within the noise.

Noise: Gaussian counts (``noise_counts``) plus a slow sway of 1 % of the span
at 0.7 Hz, the hand not held perfectly still. Moves between poses are smooth
(smoothstep over ``transition_s``).

:func:`timed_recording` is the whole sequence on a timer (``pose_s`` per pose,
looping); :func:`move_recording` is one move to a pose and the hold after it,
for a glove that changes pose on cue (``handrig sim-glove --calibration --cue``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from handrig.devices.glove_calibration import CALIBRATION_STEPS, GloveConfig
from handrig.devices.glove_recording import GloveRecording
from handrig.errors import DataError
from handrig.pose.imu_mount import IMU_STEPS, imu_quaternion

POSE_NAMES: tuple[str, ...] = tuple(name for name, _ in CALIBRATION_STEPS)
"""The poses in the order ``handrig calibrate glove`` asks for them."""
IMU_POSE_NAMES: tuple[str, ...] = tuple(name for name, _ in IMU_STEPS)
"""The two forearm poses that follow when the glove has an IMU."""
FOREARM_ROLL_DEG: dict[str, float] = {"palm-vertical": 90.0}
"""The forearm's roll (about its length, thumb up positive) per pose; level palm down
(0) in every other pose."""

SWAY_HZ = 0.7
SWAY_FRACTION = 0.01

# Fraction of the open -> closed span per pose; a key is a curve name without its
# hand prefix ("ThumbCMCx"), or a finger joint suffix ("MCPy": every finger's MCP
# flexion). Negative: past the open reading (away from closing). Unlisted: 0.
POSE_FRACTIONS: dict[str, dict[str, float]] = {
    "open": {},
    "fist": {"ThumbCMCx": 0.45, "ThumbCMCy": 1.0, "ThumbCMCz": 0.6, "ThumbMCPy": 0.7,
             "ThumbIPy": 0.6, "MCPy": 1.0, "PIPy": 1.0, "DIPy": 1.0},
    "thumb-oppose": {"ThumbCMCx": 1.0, "ThumbCMCy": 0.55, "ThumbCMCz": 1.0, "ThumbMCPy": 0.4,
                     "ThumbIPy": 0.3, "IndexMCPy": 0.1, "MiddleMCPy": 0.15, "RingMCPy": 0.3,
                     "PinkyMCPy": 0.45, "PinkyPIPy": 0.4},
    "thumb-spread": {"ThumbCMCx": 0.1, "ThumbCMCy": -0.3, "ThumbCMCz": -0.1},
    "forearm-level": {},
    "palm-vertical": {},
}


def pose_fraction(pose: str, curve: str) -> float:
    """How far ``curve`` is closed in ``pose`` (0 open, 1 fully closed)."""
    table = POSE_FRACTIONS[pose]
    name = curve[2:] if curve[:2] in ("ri", "le") else curve
    if name in table:
        return table[name]
    if not name.startswith("Thumb"):
        for suffix in ("MCPy", "PIPy", "DIPy"):
            if name.endswith(suffix):
                return table.get(suffix, 0.0)
    return 0.0


@dataclass(frozen=True)
class ScriptedSensors:
    """The emulated glove's sensors: per raw channel, the reading open and fully closed.

    ``curves[k]`` is the control curve raw channel ``k`` follows (the first
    calibrated channel reading it), ``""`` for a channel nothing calibrates
    (it stays at its open reading).
    """

    open_raw: np.ndarray  # (n_raw,) counts
    closed_raw: np.ndarray  # (n_raw,) counts
    curves: tuple[str, ...]
    full_scale: float = 4095.0

    @classmethod
    def from_config(cls, cfg: GloveConfig, *, n_raw: int = 0, travel: float = 0.85,
                    full_scale: float = 4095.0) -> ScriptedSensors:
        """A glove like the one ``cfg`` was calibrated for, whose sensors travel
        ``travel`` of the configured span, centred on it: a calibration of it
        must find new ranges, not the configured ones."""
        if not 0.1 <= travel <= 1.0:
            raise DataError(f"sensor travel {travel} out of range 0.1..1")
        width = max([n_raw, *(ch.raw_index() + 1 for ch in cfg.channels)])
        open_raw = np.full(width, full_scale / 2)
        closed_raw = open_raw.copy()
        curves = [""] * width
        for ch in cfg.channels:
            k = ch.raw_index()
            if curves[k]:
                continue
            mid, half = (ch.raw_open + ch.raw_closed) / 2, (ch.raw_closed - ch.raw_open) / 2
            open_raw[k] = np.clip(round(mid - travel * half), 0, full_scale)
            closed_raw[k] = np.clip(round(mid + travel * half), 0, full_scale)
            curves[k] = ch.curve
        return cls(open_raw, closed_raw, tuple(curves), full_scale)

    @property
    def n_raw(self) -> int:
        return len(self.open_raw)

    def pose_raw(self, pose: str) -> np.ndarray:
        """The noiseless reading (n_raw,) in ``pose``."""
        if pose not in POSE_FRACTIONS:
            raise DataError(f"unknown calibration pose {pose!r}: one of {', '.join(POSE_NAMES)}")
        frac = np.array([pose_fraction(pose, c) if c else 0.0 for c in self.curves])
        return np.clip(self.open_raw + frac * (self.closed_raw - self.open_raw),
                       0.0, self.full_scale)

    def describe(self) -> list[str]:
        """One line per calibrated raw channel: its curve and scripted range."""
        return [f"  ch{k:<2} {c:<14} open {self.open_raw[k]:6.0f}  closed "
                f"{self.closed_raw[k]:6.0f}"
                for k, c in enumerate(self.curves) if c]


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _path(sensors: ScriptedSensors, legs: Sequence[tuple[str, str, float]], transition_s: float,
          rate_hz: float, noise_counts: float, seed: int, t_offset_s: float = 0.0,
          imu_mount: Rotation | None = None) -> GloveRecording:
    """``legs``: (from pose, to pose, seconds); each leg moves during its first
    ``transition_s`` and holds for the rest. With ``imu_mount`` the recording carries
    the quaternion of an IMU mounted so (the forearm level, heading 30 deg, rolled per
    :data:`FOREARM_ROLL_DEG`)."""
    if rate_hz <= 0 or noise_counts < 0 or transition_s < 0:
        raise DataError("rate must be positive, noise and transition zero or positive")
    rng = np.random.default_rng(seed)
    rows, times, rolls = [], [], []
    t0 = 0.0
    for start, end, seconds in legs:
        if seconds <= transition_s:
            raise DataError(f"a pose lasts {seconds:g} s, not longer than its "
                            f"{transition_s:g} s move")
        t = np.arange(round(seconds * rate_hz)) / rate_hz
        a, b = sensors.pose_raw(start), sensors.pose_raw(end)
        s = _smoothstep(t / transition_s) if transition_s > 0 else np.ones_like(t)
        rows.append(a + s[:, None] * (b - a))
        ra, rb = FOREARM_ROLL_DEG.get(start, 0.0), FOREARM_ROLL_DEG.get(end, 0.0)
        rolls.append(ra + s * (rb - ra))
        times.append(t0 + t)
        t0 += len(t) / rate_hz
    t_all = np.concatenate(times)
    raw = np.concatenate(rows)
    span = np.abs(sensors.closed_raw - sensors.open_raw)
    sway = SWAY_FRACTION * span * np.sin(2 * np.pi * SWAY_HZ * (t_all + t_offset_s))[:, None]
    raw = raw + sway + rng.normal(0.0, noise_counts, raw.shape) * (span > 0)
    raw = np.clip(np.rint(raw), 0.0, sensors.full_scale)
    n = len(t_all)
    names = tuple(c or f"ch{k}" for k, c in enumerate(sensors.curves))
    quat = None
    if imu_mount is not None:
        forearm = Rotation.from_euler("ZX", np.column_stack(
            [np.full(n, 30.0), np.concatenate(rolls)]), degrees=True)
        quat = imu_quaternion(forearm, imu_mount)
    return GloveRecording(t_all, raw, np.zeros(n, dtype=np.int64), names, quat, rate_hz,
                          {"source": "sim/calibration_motion.py"})


def timed_recording(sensors: ScriptedSensors, *, pose_s: float, transition_s: float = 0.5,
                    rate_hz: float = 200.0, noise_counts: float = 6.0, seed: int = 0,
                    imu_mount: Rotation | None = None) -> GloveRecording:
    """The poses in :data:`POSE_NAMES` order (then :data:`IMU_POSE_NAMES` with an
    ``imu_mount``), ``pose_s`` each (the move into a pose at its start); played in a
    loop, the last pose moves back to the first."""
    names = pose_names(imu_mount is not None)
    legs = [(names[i - 1], name, pose_s) for i, name in enumerate(names)]
    return _path(sensors, legs, transition_s, rate_hz, noise_counts, seed,
                 imu_mount=imu_mount)


def pose_names(imu: bool) -> tuple[str, ...]:
    """The poses of a calibration, with or without the IMU's two."""
    return POSE_NAMES + IMU_POSE_NAMES if imu else POSE_NAMES


def move_recording(sensors: ScriptedSensors, start: str, end: str, *, transition_s: float = 0.5,
                   hold_s: float = 2.0, rate_hz: float = 200.0, noise_counts: float = 6.0,
                   seed: int = 0, imu_mount: Rotation | None = None) -> GloveRecording:
    """One move from pose ``start`` to ``end`` over ``transition_s``, then ``hold_s``
    in ``end`` (loop it from ``transition_s`` to hold as long as needed)."""
    return _path(sensors, [(start, end, transition_s + hold_s)], transition_s, rate_hz,
                 noise_counts, seed, imu_mount=imu_mount)
