"""Glove calibration: raw channel counts to control-curve degrees, and the glove config.

``config/glove.toml`` (written by ``handrig calibrate glove``)::

    [glove]
    format = "frames"          # "frames" (firmware_protocol/SPEC.md) or "opengloves"
    port = "/dev/ttyACM0"      # default for `handrig run` when --glove is not given
    baud = 115200
    analog_max = 4095          # OpenGloves value range: 1023 (AVR) or 4095 (ESP32)
    estop_letter = "N"         # OpenGloves button letter that acts as relax / e-stop
    rate_hz = 200.0            # the glove's nominal frame rate (a BVH take's frame rate)

    [filter]                   # One Euro filter on the calibrated degrees
    min_cutoff_hz = 1.5
    beta = 0.02                # cutoff Hz per deg/s
    d_cutoff_hz = 1.0

    [imu]
    order = "xyzw"             # component order the source delivers (frames: xyzw)
    world = "ENU"              # world frame of the source's quaternion (frames: ENU)
    mount_xyzw = [0.0, 0.0, 0.0, 1.0]  # forearm frame expressed in the IMU frame

    [forearm]                  # used when the glove has no IMU (OpenGloves)
    inclination_deg = 0.0      # -90 hanging down .. +90 pointing up
    rotation_deg = 0.0         # 0 palm down, +90 palm vertical thumb up, 180 palm up

    [[channels]]
    index = 0                  # raw channel (frames); or letter = "A" for OpenGloves
    curve = "riThumbCMCx"
    raw_open = 1200            # reading with the hand open
    raw_closed = 2800          # reading in a fist (may be below raw_open: reversed sensor)
    open_deg = 0.0             # the curve's angle with the hand open
    closed_deg = 15.0          # ... and in a fist

Each channel maps linearly from ``raw_open -> open_deg`` to ``raw_closed ->
closed_deg`` and is clamped to that degree range. With ``format = "frames"`` each
raw channel the glove sends is read by exactly one entry: the indices are 0..n-1,
each once (a duplicated or missing index is refused). With OpenGloves several
entries may read the same letter (one thumb value can drive CMC flexion and
abduction).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from firmware_protocol.opengloves import BUTTON_LETTERS, CHANNEL_KEYS
from handrig import hand
from handrig.config.loading import CONFIG_DIR, load
from handrig.devices.glove_recording import GloveRecording
from handrig.errors import ConfigError, DataError
from handrig.pose import kernels
from handrig.pose.filters import OneEuroFilter

FloatArray = NDArray[np.float64]
DEFAULT_GLOVE_PATH = CONFIG_DIR / "glove.toml"
MAX_RAW_CHANNELS = 16
RAW_MAX = 65535
"""The largest raw reading: frames carry uint16 channels (OpenGloves at most 4095)."""
OPENGLOVES_KEYS: dict[str, int] = {
    **{k: i for i, k in enumerate(CHANNEL_KEYS)},
    **{k.strip("()"): i for i, k in enumerate(CHANNEL_KEYS)},
}
"""OpenGloves key (``A``, ``(AB)`` or ``AB``, ``F``, ``G``, ``P``) -> raw channel index."""


# The poses `handrig calibrate glove` asks for, in order (name, what to do); the
# calibration emulator (sim/calibration_motion.py) performs the same ones.
CALIBRATION_STEPS: tuple[tuple[str, str], ...] = (
    ("open", "Open hand: fingers straight and together, thumb relaxed beside the index."),
    ("fist", "Fist: close every finger, thumb wrapped over the middle finger."),
    ("thumb-oppose", "Thumb to little finger: touch the two tips together."),
    ("thumb-spread", "Thumb spread: move the thumb as far from the index as is comfortable."),
)


@dataclass(frozen=True)
class ChannelCalibration:
    """One raw channel -> one control curve (see the module docstring)."""

    curve: str
    raw_open: float
    raw_closed: float
    open_deg: float
    closed_deg: float
    index: int = -1
    letter: str = ""

    def check(self) -> None:
        if self.curve not in hand.CURVE_NAMES:
            import difflib

            close = difflib.get_close_matches(self.curve, hand.CURVE_NAMES, n=1)
            raise ConfigError(
                "unknown control curve", key="curve", value=self.curve,
                allowed=(f"did you mean {close[0]!r}? " if close else "")
                + "one of the 50 curve names, e.g. riIndexMCPy",
            )
        if (self.index >= 0) == bool(self.letter):
            raise ConfigError(
                "give exactly one of index (raw channel) or letter (OpenGloves key)",
                key="index" if self.index >= 0 else None,
                allowed="index = 0..15, or letter = A..E, AB..EB, F, G, P",
            )
        if self.index >= MAX_RAW_CHANNELS:
            raise ConfigError("raw channel out of range", key="index", value=self.index,
                              allowed=f"0..{MAX_RAW_CHANNELS - 1}")
        if self.letter and self.letter not in OPENGLOVES_KEYS:
            raise ConfigError("unknown OpenGloves key", key="letter", value=self.letter,
                              allowed="A..E (fingers), AB..EB (splay), F, G (joystick), P")
        for name in ("raw_open", "raw_closed"):
            v = getattr(self, name)
            if not 0 <= v <= RAW_MAX:
                raise ConfigError("outside the range of a raw reading", key=name, value=v,
                                  allowed=f"0..{RAW_MAX} (a uint16 channel)")
        if self.raw_open == self.raw_closed:
            raise ConfigError(
                "raw_open equals raw_closed: the sensor did not move during calibration",
                key="raw_closed", value=self.raw_closed,
                allowed="a different reading; run `handrig calibrate glove` again",
            )
        if self.open_deg == self.closed_deg:
            raise ConfigError("open_deg equals closed_deg", key="closed_deg",
                              value=self.closed_deg)
        low, high = hand.anatomical_limits_deg(self.curve)
        for name in ("open_deg", "closed_deg"):
            v = getattr(self, name)
            if not low <= v <= high:
                raise ConfigError(f"outside the joint limits of {self.curve}", key=name,
                                  value=v, allowed=f"{low:g}..{high:g} degrees")

    def raw_index(self) -> int:
        """The raw channel this entry reads (the letter resolved for OpenGloves)."""
        return self.index if self.index >= 0 else OPENGLOVES_KEYS[self.letter]


@dataclass(frozen=True)
class GlovePort:
    """Which glove and how to talk to it."""

    format: Literal["frames", "opengloves"] = "frames"
    port: str = ""
    baud: int = 115200
    analog_max: int = 4095
    estop_letter: str = "N"
    rate_hz: float = 200.0  # the glove's nominal frame rate: a BVH take's frame rate

    def check(self) -> None:
        if self.analog_max not in (1023, 4095):
            raise ConfigError("unsupported ANALOG_MAX", key="analog_max",
                              value=self.analog_max, allowed="1023 (AVR) or 4095 (ESP32)")
        if self.estop_letter not in BUTTON_LETTERS:
            raise ConfigError("not an OpenGloves button letter", key="estop_letter",
                              value=self.estop_letter, allowed=", ".join(BUTTON_LETTERS))
        if self.baud <= 0:
            raise ConfigError("must be positive", key="baud", value=self.baud)
        if not 10.0 <= self.rate_hz <= 2000.0:
            raise ConfigError("glove rate out of range", key="rate_hz", value=self.rate_hz,
                              allowed="10..2000 Hz, the rate the glove sends frames at")


@dataclass(frozen=True)
class FilterSettings:
    """One Euro filter parameters (applied to the calibrated degrees)."""

    enabled: bool = True
    min_cutoff_hz: float = 1.5
    beta: float = 0.02
    d_cutoff_hz: float = 1.0

    def check(self) -> None:
        for name in ("min_cutoff_hz", "d_cutoff_hz"):
            value = getattr(self, name)
            # a cutoff at or above half the glove's rate filters nothing; NaN is refused
            if not 0.01 <= value <= 1000.0:
                raise ConfigError("cutoff out of range", key=name, value=value,
                                  allowed="0.01..1000 Hz")
        if self.beta < 0:
            raise ConfigError("must be zero or positive", key="beta", value=self.beta)


@dataclass(frozen=True)
class ImuSettings:
    """How the source's quaternion is laid out, and how the IMU sits on the forearm.

    ``mount_xyzw`` is the forearm frame's orientation in the IMU's body frame
    (it rotates forearm-frame vectors into IMU-frame vectors), so the forearm's
    orientation in the world is ``q_imu * mount``.
    """

    order: Literal["xyzw", "wxyz"] = "xyzw"
    world: Literal["ENU", "NED"] = "ENU"
    mount_xyzw: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    def check(self) -> None:
        norm = math.sqrt(sum(v * v for v in self.mount_xyzw))
        if abs(norm - 1.0) > 1e-3:
            raise ConfigError("mount rotation is not a unit quaternion", key="mount_xyzw",
                              value=list(self.mount_xyzw), allowed="norm 1 (x, y, z, w)")


@dataclass(frozen=True)
class FixedForearm:
    """Forearm orientation to assume when the glove has no IMU."""

    inclination_deg: float = 0.0
    rotation_deg: float = 0.0

    def check(self) -> None:
        if not -90.0 <= self.inclination_deg <= 90.0:
            raise ConfigError("inclination out of range", key="inclination_deg",
                              value=self.inclination_deg, allowed="-90..90 degrees")
        if not -360.0 <= self.rotation_deg <= 360.0:
            raise ConfigError("rotation out of range", key="rotation_deg",
                              value=self.rotation_deg, allowed="-360..360 degrees")


@dataclass(frozen=True)
class GloveConfig:
    """The whole ``config/glove.toml``."""

    glove: GlovePort = GlovePort()
    filter: FilterSettings = FilterSettings()
    imu: ImuSettings = ImuSettings()
    forearm: FixedForearm = FixedForearm()
    channels: tuple[ChannelCalibration, ...] = field(default_factory=tuple)

    def check(self) -> None:
        if not self.channels:
            raise ConfigError("no [[channels]]: nothing maps the glove to the hand",
                              key="channels", allowed="at least one [[channels]] table")
        for i, ch in enumerate(self.channels):
            if self.glove.format == "frames" and ch.letter:
                raise ConfigError("letter is for OpenGloves; frames use index",
                                  key=f"channels[{i}].letter", value=ch.letter)
            if self.glove.format == "opengloves" and ch.index >= len(CHANNEL_KEYS):
                raise ConfigError("OpenGloves has 13 channels", key=f"channels[{i}].index",
                                  value=ch.index, allowed="0..12, or a letter")
        seen: dict[str, int] = {}
        for i, ch in enumerate(self.channels):
            if ch.curve in seen:
                raise ConfigError(f"curve already driven by channels[{seen[ch.curve]}]",
                                  key=f"channels[{i}].curve", value=ch.curve)
            seen[ch.curve] = i
        if self.glove.format == "frames":
            self._check_indices()

    def _check_indices(self) -> None:
        """Frames: raw channels 0..n-1, each read by one entry (a duplicate is a copy-paste
        slip that leaves a sensor unread; a gap, a sensor nobody reads)."""
        first: dict[int, int] = {}
        for i, ch in enumerate(self.channels):
            if ch.index in first:
                raise ConfigError(
                    f"raw channel {ch.index} already read by channels[{first[ch.index]}] "
                    f"({self.channels[first[ch.index]].curve})", key=f"channels[{i}].index",
                    value=ch.index, allowed=f"each index once, 0..{len(self.channels) - 1}")
            first[ch.index] = i
        missing = sorted(set(range(max(first) + 1)) - set(first))
        if missing:
            last = first[max(first)]
            raise ConfigError(
                f"raw channel {missing[0]} is read by no [[channels]] entry (indices "
                f"{', '.join(str(k) for k in sorted(first))})", key=f"channels[{last}].index",
                value=self.channels[last].index,
                allowed=f"indices 0..{len(self.channels) - 1}, each once: add the entry for "
                f"channel {missing[0]} or renumber")

    @property
    def curves(self) -> tuple[str, ...]:
        """The control curves, in ``channels`` order."""
        return tuple(c.curve for c in self.channels)


def default_glove_path() -> Path:
    """The glove file read by default: the user's calibrated ``glove.toml``
    (:func:`handrig.config.paths.config_file`) when there is one, else the installed one."""
    from handrig.config.paths import config_file

    return config_file(DEFAULT_GLOVE_PATH.name)


def load_glove_config(path: str | Path | None = None) -> GloveConfig:
    """Load ``path`` (default :func:`default_glove_path`); errors name the file and key."""
    return load(path or default_glove_path(), GloveConfig)


def glove_config_to_toml(cfg: GloveConfig) -> dict[str, Any]:
    """Plain data for ``tomli_w`` (the inverse of :func:`load_glove_config`)."""
    chans = []
    for c in cfg.channels:
        d: dict[str, Any] = {"index": c.index} if c.index >= 0 else {"letter": c.letter}
        d.update(curve=c.curve, raw_open=c.raw_open, raw_closed=c.raw_closed,
                 open_deg=c.open_deg, closed_deg=c.closed_deg)
        chans.append(d)
    g, f, m, a = cfg.glove, cfg.filter, cfg.imu, cfg.forearm
    return {
        "glove": {"format": g.format, "port": g.port, "baud": g.baud,
                  "analog_max": g.analog_max, "estop_letter": g.estop_letter,
                  "rate_hz": g.rate_hz},
        "filter": {"enabled": f.enabled, "min_cutoff_hz": f.min_cutoff_hz, "beta": f.beta,
                   "d_cutoff_hz": f.d_cutoff_hz},
        "imu": {"order": m.order, "world": m.world, "mount_xyzw": list(m.mount_xyzw)},
        "forearm": {"inclination_deg": a.inclination_deg, "rotation_deg": a.rotation_deg},
        "channels": chans,
    }


class GloveCalibration:
    """Vectorised raw -> degrees for the calibrated channels (k of them).

    ``calibrate(raw, out)``: ``raw`` (n_raw,) counts -> ``out`` (k,) degrees in
    :attr:`curves` order, linear between the open and closed readings and
    clamped to ``[min(open_deg, closed_deg), max(...)]``. Allocates nothing.
    """

    def __init__(self, channels: Sequence[ChannelCalibration]) -> None:
        if not channels:
            raise ConfigError("a glove calibration needs at least one channel")
        self.channels = tuple(channels)
        self.curves: tuple[str, ...] = tuple(c.curve for c in channels)
        self.raw_index = np.array([c.raw_index() for c in channels], dtype=np.intp)
        raw_open = np.array([c.raw_open for c in channels], dtype=np.float64)
        raw_closed = np.array([c.raw_closed for c in channels], dtype=np.float64)
        open_deg = np.array([c.open_deg for c in channels], dtype=np.float64)
        closed_deg = np.array([c.closed_deg for c in channels], dtype=np.float64)
        self._gain = (closed_deg - open_deg) / (raw_closed - raw_open)
        # deg = raw * gain + offset
        self._offset = open_deg - raw_open * self._gain
        self._lo = np.minimum(open_deg, closed_deg)
        self._hi = np.maximum(open_deg, closed_deg)
        self._raw_open, self._raw_closed = raw_open, raw_closed
        # what a non-finite reading is replaced by: the channel's last good value (open
        # hand before any), so it never reaches the filter, whose state it would poison
        self._last_good = open_deg.copy()
        self.nonfinite = 0
        self.n_raw_needed = int(self.raw_index.max()) + 1

    @classmethod
    def from_config(cls, cfg: GloveConfig) -> GloveCalibration:
        """The calibration of a loaded :class:`GloveConfig`."""
        return cls(cfg.channels)

    def __len__(self) -> int:
        return len(self.curves)

    def calibrate(self, raw: FloatArray, out: FloatArray | None = None) -> FloatArray:
        """Raw counts (n_raw,) -> degrees (k,), clamped to each channel's range."""
        if out is None:
            out = np.empty(len(self.curves))
        r = self._checked_raw(raw)
        self.nonfinite += kernels.calibrate(r, self.raw_index, self._gain, self._offset,
                                            self._lo, self._hi, self._last_good, out)
        return out

    def kernel_state(self) -> tuple[NDArray[np.intp], FloatArray, FloatArray, FloatArray,
                                    FloatArray, FloatArray]:
        """The arrays a compiled step that fuses this calibration reads (and, for the last
        good values, updates in place): (raw_index, gain, offset, lo, hi, last_good)."""
        return (self.raw_index, self._gain, self._offset, self._lo, self._hi,
                self._last_good)

    def checked_raw(self, raw: FloatArray) -> FloatArray:
        """``raw`` as contiguous float64, long enough for every calibrated channel
        (DataError naming the fix otherwise)."""
        return self._checked_raw(raw)

    def _checked_raw(self, raw: FloatArray) -> FloatArray:
        """``raw`` as contiguous float64, long enough for every calibrated channel."""
        r = np.ascontiguousarray(raw, dtype=np.float64)
        if r.ndim != 1 or len(r) < self.n_raw_needed:
            raise DataError(
                f"the glove sent {len(r)} channels but the calibration reads channel "
                f"{self.n_raw_needed - 1}; check [[channels]] in glove.toml or recalibrate"
            )
        return r

    def to_raw(self, degrees: FloatArray) -> FloatArray:
        """Inverse map: degrees (..., k) -> raw counts (..., k), e.g. to synthesise a
        glove recording from mocap curves (values outside the range extrapolate)."""
        return (np.asarray(degrees, dtype=np.float64) - self._offset) / self._gain


class GloveControls:
    """Raw glove sample -> the map's control vector: calibrate, filter, reorder.

    ``controls(raw, t_s, out)`` writes ``out`` (len(control_names),) degrees in
    ``control_names`` order (e.g. the map's ``controls``); every control must be
    driven by a calibrated channel. This is the ``controls_from_raw`` callable of
    :class:`handrig.loop.rig.Rig`. Allocates nothing per call.
    """

    def __init__(
        self,
        calibration: GloveCalibration,
        control_names: Sequence[str],
        filter_settings: FilterSettings | None = None,
    ) -> None:
        missing = [c for c in control_names if c not in calibration.curves]
        if missing:
            raise ConfigError(
                f"the map's control(s) {', '.join(missing)} have no glove channel",
                key="channels", allowed="add a [[channels]] entry with curve = "
                f"{missing[0]!r} to glove.toml (or run `handrig calibrate glove`)",
            )
        self.calibration = calibration
        self.control_names = tuple(control_names)
        self._perm = np.array([calibration.curves.index(c) for c in control_names],
                              dtype=np.intp)
        self._deg = np.empty(len(calibration))
        fs = filter_settings or FilterSettings(enabled=False)
        self.filter: OneEuroFilter | None = (
            OneEuroFilter(len(calibration), fs.min_cutoff_hz, fs.beta, fs.d_cutoff_hz)
            if fs.enabled else None
        )
        # the arrays the fused kernel works on, through the parts' public accessors
        self._cal_state = calibration.kernel_state()
        d = self._deg  # no filter: placeholders the kernel does not read
        self._filter_state = (self.filter.kernel_state() if self.filter is not None
                              else (d, d, d, d, d))

    @classmethod
    def from_config(cls, cfg: GloveConfig, control_names: Sequence[str]) -> GloveControls:
        """Calibration and filter of ``cfg``, ordered as ``control_names``."""
        return cls(GloveCalibration.from_config(cfg), control_names, cfg.filter)

    def __call__(self, raw: FloatArray, t_s: float, out: FloatArray) -> FloatArray:
        cal = self.calibration
        r = cal.checked_raw(raw)
        f = self.filter
        if f is None:
            cal.nonfinite += kernels.glove_controls(
                r, *self._cal_state, self._deg, False, False, 0.0, *self._filter_state,
                self._perm, out)
            return out
        prime, te = f.advance(t_s)
        cal.nonfinite += kernels.glove_controls(
            r, *self._cal_state, self._deg, True, prime, te, *self._filter_state,
            self._perm, out)
        return out

    def reset(self) -> None:
        """Restart the filter (e.g. after the glove was lost and came back)."""
        if self.filter is not None:
            self.filter.reset()


def recording_from_degrees(
    calibration: GloveCalibration,
    t_s: FloatArray,
    degrees: FloatArray,
    *,
    quat_xyzw: FloatArray | None = None,
    buttons: NDArray[np.int64] | None = None,
    full_scale: float = 4095.0,
    meta: dict[str, str] | None = None,
) -> GloveRecording:
    """The glove recording that ``calibration`` would read as ``degrees`` (n, k) in
    :attr:`GloveCalibration.curves` order: the inverse map, rounded and clipped to
    0..``full_scale`` counts. E.g. control curves from mocap -> a demo glove stream.
    When several curves share a raw channel, the first one sets it."""
    deg = np.asarray(degrees, dtype=np.float64)
    n = len(t_s)
    if deg.shape != (n, len(calibration)):
        raise DataError(f"degrees has shape {deg.shape}, expected ({n}, {len(calibration)})")
    raw_k = np.clip(np.rint(calibration.to_raw(deg)), 0.0, full_scale)
    raw = np.zeros((n, calibration.n_raw_needed))
    done: set[int] = set()
    for j, k in enumerate(calibration.raw_index.tolist()):
        if k not in done:
            raw[:, k] = raw_k[:, j]
            done.add(k)
    names = tuple(
        next((c for c, i in zip(calibration.curves, calibration.raw_index.tolist(),
                                strict=True) if i == k), f"ch{k}")
        for k in range(calibration.n_raw_needed)
    )
    return GloveRecording(
        np.asarray(t_s, dtype=np.float64), raw,
        np.zeros(n, dtype=np.int64) if buttons is None else np.asarray(buttons, np.int64),
        names, None if quat_xyzw is None else np.asarray(quat_xyzw, dtype=np.float64),
        0.0, dict(meta or {}),
    )

