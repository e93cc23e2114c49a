"""The rig config: which servo drives which joint, and how (``config/rig.toml``).

Shared by the servo driver (degrees -> goal ticks) and the bus emulator (ticks ->
the simulated joint), so both sides of the loopback use one calibration.

A servo's calibration is data here: its zero (``zero_ticks``, the servo's position
at joint angle 0), ``direction``, ``gear_ratio`` (servo turns per joint turn, a
tendon or gear reduction) and joint limits in degrees (vocabulary convention,
flexion positive). What a tick is, which IDs, bauds, gains and return delays a
servo takes, is its driver's (:mod:`handrig.devices.servo.positions` converts,
:func:`handrig.devices.servo.models.check_rig` checks a rig against the servos it
names). A servo never receives a goal outside ``[min_deg, max_deg]``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from handrig.config.loading import check_joint_name, load
from handrig.config.rig_files import resolve_rig_file
from handrig.errors import ConfigError
from handrig.hand import anatomical_limits_deg

READ_PARTS_MAX = 8
"""The most parts a present-state read is split into (``[bus] read_parts``, and the
loop's own splitting when reads find no room between the glove's frames)."""


@dataclass(frozen=True)
class ServoCalibration:
    """One servo: its bus ID, the joint it drives, and the mapping between them."""

    id: int
    joint: str
    model: str = ""  # the servo's model as its driver names it (empty: the driver's default)
    zero_ticks: int = 2048
    direction: Literal[1, -1] = 1
    gear_ratio: float = 1.0
    min_deg: float = -90.0
    max_deg: float = 90.0

    def check(self) -> None:
        if self.id < 0:
            raise ConfigError("servo ID out of range", key="id", value=self.id,
                              allowed="0 or more (and at most the bus's own maximum)")
        check_joint_name(self.joint, "joint")
        if not 0.1 <= self.gear_ratio <= 20.0:
            raise ConfigError(
                "implausible gear ratio", key="gear_ratio", value=self.gear_ratio,
                allowed="0.1..20 servo turns per joint turn",
            )
        if self.min_deg >= self.max_deg:
            raise ConfigError(
                "inverted limit: min_deg must be below max_deg", key="min_deg",
                value=[self.min_deg, self.max_deg], allowed="min_deg < max_deg",
            )
        low, high = anatomical_limits_deg(self.joint)
        if self.min_deg < low or self.max_deg > high:
            raise ConfigError(
                f"servo limits exceed the anatomical range of {self.joint}",
                key="min_deg", value=[self.min_deg, self.max_deg], allowed=f"[{low}, {high}]",
            )


@dataclass(frozen=True)
class BusConfig:
    """The serial bus: port path (or ``"sim"``, the simulated rig), baud rate, timing.
    An empty port names none: a command that needs one asks for ``--port``."""

    port: str = ""
    baud: int = 1_000_000
    read_every: int = 4  # read present state every N cycles (Fast Sync Read)
    read_parts: int = 1  # each read asks 1/N of the servos, in turn (shorter reads); the
    # loop splits reads further (up to READ_PARTS_MAX) when they find no gap between frames
    watchdog_ms: int = 100  # Bus Watchdog (units of 20 ms on the wire); 0 disables

    def check(self) -> None:
        if self.baud <= 0:  # which bauds the servos take is their driver's to check
            raise ConfigError("not a baud rate", key="baud", value=self.baud,
                              allowed="a positive number of bits per second")
        if self.read_every < 1:
            raise ConfigError("must be at least 1", key="read_every", value=self.read_every)
        if not 1 <= self.read_parts <= READ_PARTS_MAX:
            raise ConfigError("out of range", key="read_parts", value=self.read_parts,
                              allowed=f"1 (every servo in each read) to {READ_PARTS_MAX}")
        if not 0 <= self.watchdog_ms <= 127 * 20:
            raise ConfigError(
                "watchdog out of range", key="watchdog_ms", value=self.watchdog_ms,
                allowed="0 (off) or 20..2540 ms",
            )


SIM_PORT = "sim"
"""The port name that asks for the simulated rig (the byte-level emulator and MuJoCo)."""

PORT_ADVICE = ("--port PORT (the servo adapter, best by its stable name "
               "/dev/serial/by-id/usb-FTDI_...: docs/hardware.md), or --port sim for the "
               "simulated rig; `handrig setup` finds the adapter and writes [bus] port "
               "into your rig file")
"""What to do when no servo port is named: the one wording every command gives."""


def require_port(port: str | None, rig_file: str | Path | None = None, *,
                 flag: str = "--port") -> str:
    """``port`` (a flag's value, else the rig file's ``[bus] port``), or a ConfigError
    naming ``flag`` and the fix when neither names one: nothing falls back to the
    simulated rig unasked."""
    if port:
        return port
    where = f"{rig_file} names no [bus] port" if rig_file else "the rig file names no port"
    raise ConfigError(f"no servo port given ({where})", key=flag,
                      allowed=PORT_ADVICE.replace("--port", flag))


LOOP_RANGES: tuple[tuple[str, float, float, str], ...] = (
    ("glove_timeout_s", 0.01, 10.0, "s"),
    ("relax_time_s", 0.01, 10.0, "s"),
    ("resume_frames", 1, 1000, "frames"),
    ("resume_time_s", 0.01, 10.0, "s"),
    ("slew_deg_s", 1.0, 10000.0, "deg/s"),
    ("glove_poll_us", 0.0, 2000.0, "us"),
    ("warm_up_us", 0.0, 2000.0, "us"),
)
"""[loop] keys checked against a sane range: (key, lowest, highest, unit)."""


@dataclass(frozen=True)
class LoopConfig:
    """The realtime loop: rate, safety timings, slew limit, sag and the files it uses.

    Paths are relative to the rig file's folder unless absolute; empty means the
    shipped default (``config/maps/default.toml``, ``config/sag_grid.npz``,
    ``config/glove.toml``).
    """

    rate_hz: float = 200.0  # the fixed loop's rate (mode "fixed")
    mode: Literal["glove", "fixed"] = "glove"  # a cycle per glove frame, or at rate_hz
    floor_hz: float = 100.0  # mode "glove": a write at least this often, frame or not
    ceiling_hz: float = 1000.0  # mode "glove": at most this many writes per second
    catch_up: bool = True  # mode "glove": a frame superseded before its cycle still gets one
    # mode "glove": poll the glove's port from this long before the frame is expected
    # until this long after, instead of sleeping on it (0: always sleep); see GloveTrigger
    glove_poll_us: float = 150.0
    # mode "glove": this long before the frame is expected, the loop runs the frame's
    # path once on scratch data, so that its code is in the CPU's caches when the
    # frame comes (0: no warm-up); see GloveTrigger
    warm_up_us: float = 150.0
    # mode "glove", with warm_up_us > 0: from the warm-up until the frame's Sync Write is
    # out, idle CPUs poll instead of halting (a CPU latency request; needs write access
    # to /dev/cpu_dma_latency, see docs/hardware.md); see handrig.realtime.CpuWake
    keep_cpus_awake: bool = True
    glove_timeout_s: float = 0.25  # silence or garbage longer than this: ease to relaxed
    relax_time_s: float = 1.0  # how long easing to the relaxed pose takes
    resume_frames: int = 3  # good glove frames in a row after a loss before following again
    resume_time_s: float = 0.3  # how long easing back to the glove's pose takes
    slew_deg_s: float = 720.0  # max joint speed commanded in normal running
    sag_gain: float = 1.0  # 0 = no passive sag, 1 = the full baked sag
    left_hand: Literal["mirror", "map", "relaxed"] = "map"
    left_forearm_deg: tuple[float, float] = (-90.0, 0.0)  # no IMU there: assumed hanging
    realtime_priority: int = 20  # SCHED_FIFO priority of the loop thread; 0 = normal
    pin_cpu: bool = True  # loop thread on the last CPU, emulators it starts on the others
    map: str = ""
    sag_grid: str = ""
    glove: str = ""

    def check(self) -> None:
        if not 10.0 <= self.rate_hz <= 2000.0:
            raise ConfigError("loop rate out of range", key="rate_hz", value=self.rate_hz,
                              allowed="10..2000 Hz")
        if self.mode not in ("glove", "fixed"):
            raise ConfigError("loop mode unknown", key="mode", value=self.mode,
                              allowed="'glove' (a cycle per glove frame) or 'fixed' (rate_hz)")
        if not 10.0 <= self.floor_hz <= 2000.0:
            raise ConfigError("floor rate out of range", key="floor_hz", value=self.floor_hz,
                              allowed="10..2000 Hz")
        if not self.floor_hz <= self.ceiling_hz <= 5000.0:
            raise ConfigError("ceiling rate out of range", key="ceiling_hz",
                              value=self.ceiling_hz,
                              allowed=f"floor_hz ({self.floor_hz:g})..5000 Hz")
        for name, low, high, unit in LOOP_RANGES:
            value = getattr(self, name)
            if not low <= value <= high:
                raise ConfigError("out of range", key=name, value=value,
                                  allowed=f"{low:g}..{high:g} {unit}")
        if not 0 <= self.realtime_priority <= 99:
            raise ConfigError("out of range", key="realtime_priority",
                              value=self.realtime_priority, allowed="0 (off) or 1..99")
        if not 0.0 <= self.sag_gain <= 2.0:
            raise ConfigError("sag gain out of range", key="sag_gain", value=self.sag_gain,
                              allowed="0..2")


SilenceAction = Literal["continue", "relax", "stop"]


@dataclass(frozen=True)
class SilenceConfig:
    """What the rig does about a servo with no valid reply (``[silence]``), in tiers.

    After ``warn_s`` without a valid reading the servo is named in a warning; after
    ``hold_s`` its goal is held where it was (goals still go out: a Sync Write
    needs no reply, and the Bus Watchdogs stay fed); after ``action_s`` comes
    ``action``: ``"continue"`` (the others keep following the glove, it stays
    held until it answers), ``"relax"`` (every servo eases to the relaxed pose;
    following resumes once it answers) or ``"stop"`` (the run ends, torque off).
    A servo that answers again is released towards its goals at the slew limit.
    """

    warn_s: float = 0.1
    hold_s: float = 0.25
    action_s: float = 1.0
    action: SilenceAction = "continue"

    def check(self) -> None:
        for name in ("warn_s", "hold_s", "action_s"):
            value = getattr(self, name)
            if not 0.0 < value <= 60.0:
                raise ConfigError("out of range", key=name, value=value, allowed="0..60 s")
        if not self.warn_s <= self.hold_s <= self.action_s:
            raise ConfigError("tiers out of order", key="hold_s",
                              value=[self.warn_s, self.hold_s, self.action_s],
                              allowed="warn_s <= hold_s <= action_s")
        if self.action not in ("continue", "relax", "stop"):
            raise ConfigError("unknown action", key="action", value=self.action,
                              allowed="continue, relax, stop")


HeatAction = Literal["continue", "relax", "stop"]
HEAT_HYSTERESIS_C = 3.0  # a tier ends once the servo is this far below it


@dataclass(frozen=True)
class HeatConfig:
    """What the rig does about a servo that heats up (``[heat]``), in tiers, from the
    temperatures the bus reads (about once a second).

    At ``warn_c`` the servo is named in a warning; at ``act_c`` its effort is capped
    (Goal PWM at ``relief_pwm_pct`` % of its PWM Limit: the joint then gives way to
    the load toward where it needs less, and the motor current falls), the others go
    on; at ``action_c`` comes ``action``: ``"continue"`` (keep the cap and go on),
    ``"relax"`` (every servo eases to the relaxed pose until it cools below
    ``action_c``) or ``"stop"`` (the run ends, torque off). Each tier ends
    :data:`HEAT_HYSTERESIS_C` below its threshold. ``action_c`` must be below every
    servo's own Temperature Limit, where the servo turns itself off.
    """

    warn_c: float = 55.0
    act_c: float = 60.0
    action_c: float = 65.0
    relief_pwm_pct: float = 50.0
    action: HeatAction = "relax"

    def check(self) -> None:
        for name in ("warn_c", "act_c", "action_c"):
            value = getattr(self, name)
            if not 35.0 <= value <= 95.0:
                raise ConfigError("out of range", key=name, value=value,
                                  allowed="35..95 deg C (below the servos' Temperature Limit)")
        if not self.warn_c < self.act_c < self.action_c:
            raise ConfigError("tiers out of order", key="act_c",
                              value=[self.warn_c, self.act_c, self.action_c],
                              allowed="warn_c < act_c < action_c")
        if not 10.0 <= self.relief_pwm_pct <= 100.0:
            raise ConfigError("out of range", key="relief_pwm_pct", value=self.relief_pwm_pct,
                              allowed="10..100 % of the servo's PWM Limit")
        if self.action not in ("continue", "relax", "stop"):
            raise ConfigError("unknown action", key="action", value=self.action,
                              allowed="continue, relax, stop")


# ------------------------------------------------------------ servo settings
OPERATING_MODE_NAMES = ("position", "extended_position", "current_based_position")
"""The operating modes a rig may ask for (their register values are the driver's)."""
OperatingMode = Literal["position", "extended_position", "current_based_position"]
RETURN_DELAY_SANE_US = 10_000  # no servo bus answers this late on purpose


def _check_not_negative(value: int | None, key: str, what: str) -> None:
    # the servos' own ranges are their driver's to check (devices/servo/models.py)
    if value is not None and value < 0:
        raise ConfigError(f"{what} out of range", key=key, value=value,
                          allowed="0 or more (and within the servo's own range)")


def _check_current(value: int | None, key: str) -> None:
    # each model's own maximum is its driver's to check (devices/servo/models.py)
    if value is not None and value < 1:
        raise ConfigError("current limit out of range", key=key, value=value,
                          allowed="1 mA or more (and at most the servo model's own maximum)")


def _check_mode(value: str | None) -> None:
    if value is not None and value not in OPERATING_MODE_NAMES:
        raise ConfigError("unknown operating mode", key="operating_mode", value=value,
                          allowed=", ".join(OPERATING_MODE_NAMES))


@dataclass(frozen=True)
class ServoSettingsGroup:
    """Settings for some servos that differ from ``[servo_settings]`` (e.g. side-to-side
    joints with lower gains). ``None`` keeps the value of ``[servo_settings]``."""

    ids: tuple[int, ...]
    current_limit_ma: int | None = None
    position_p_gain: int | None = None
    position_d_gain: int | None = None
    operating_mode: OperatingMode | None = None

    def check(self) -> None:
        _check_mode(self.operating_mode)
        if not self.ids:
            raise ConfigError("a group needs at least one servo ID", key="ids")
        _check_current(self.current_limit_ma, "current_limit_ma")
        _check_not_negative(self.position_p_gain, "position_p_gain", "gain")
        _check_not_negative(self.position_d_gain, "position_d_gain", "gain")


@dataclass(frozen=True)
class ServoSettings:
    """What commissioning writes to every servo (``[servo_settings]``).

    ``operating_mode``: ``"position"`` (the default), ``"extended_position"`` or
    ``"current_based_position"`` (position control whose torque is capped by the
    current limit). ``current_limit_ma``: the servo's current limit and goal current;
    ``None`` leaves the servo's own. Position P/D gains: ``None`` leaves the servo's
    own. ``return_delay_us``: how long a servo waits before it answers (0 is what a
    fast loop wants). ``groups``: per-servo differences. Which values a servo takes
    is its driver's to check (:func:`handrig.devices.servo.models.check_rig`).
    """

    operating_mode: OperatingMode = "position"
    current_limit_ma: int | None = None
    position_p_gain: int | None = None
    position_d_gain: int | None = None
    return_delay_us: int = 0
    groups: tuple[ServoSettingsGroup, ...] = ()

    def check(self) -> None:
        _check_mode(self.operating_mode)
        _check_current(self.current_limit_ma, "current_limit_ma")
        _check_not_negative(self.position_p_gain, "position_p_gain", "gain")
        _check_not_negative(self.position_d_gain, "position_d_gain", "gain")
        if not 0 <= self.return_delay_us <= RETURN_DELAY_SANE_US:  # the servo's own: its driver's
            raise ConfigError("return delay out of range", key="return_delay_us",
                              value=self.return_delay_us,
                              allowed=f"0..{RETURN_DELAY_SANE_US} us (and what the servo "
                              "takes; 0 is what a fast loop wants)")
        seen: dict[int, int] = {}
        for g, group in enumerate(self.groups):
            for servo_id in group.ids:
                if servo_id in seen:
                    raise ConfigError(f"servo ID in two groups (also groups[{seen[servo_id]}])",
                                      key=f"groups[{g}].ids", value=servo_id)
                seen[servo_id] = g

    def mode_for(self, servo_id: int) -> OperatingMode:
        """The operating mode servo ``servo_id`` runs in (its group's, else this table's)."""
        for group in self.groups:
            if servo_id in group.ids and group.operating_mode is not None:
                return group.operating_mode
        return self.operating_mode


def check_servo_settings(rig: RigConfig) -> None:
    """Groups name servos of the rig (each model's limits are its driver's to check:
    :func:`handrig.devices.servo.models.check_rig`)."""
    ids = {s.id: s for s in rig.servos}
    for g, group in enumerate(rig.servo_settings.groups):
        for servo_id in group.ids:
            if servo_id not in ids:
                raise ConfigError("no servo with this ID in [[servos]]",
                                  key=f"servo_settings.groups[{g}].ids", value=servo_id,
                                  allowed=", ".join(str(i) for i in sorted(ids)))


@dataclass(frozen=True)
class CalibrationConfig:
    """``[calibration]``: when ``handrig calibrate servos`` asks for a typed confirmation.

    ``max_zero_shift_deg``: a new zero further than this from the current one (joint
    degrees) is written only after the user types ``yes``.
    """

    max_zero_shift_deg: float = 20.0

    def check(self) -> None:
        if not 0.0 < self.max_zero_shift_deg <= 360.0:
            raise ConfigError("out of range", key="max_zero_shift_deg",
                              value=self.max_zero_shift_deg, allowed="0 < degrees <= 360")


@dataclass(frozen=True)
class GlovesConfig:
    """``[gloves]``: a glove per hand (a rig with servos for both hands). ``right`` and
    ``left`` are glove specs as ``--glove`` takes them (a port, ``opengloves:PORT``,
    ``replay:FILE.csv``; empty: none from the rig file); ``left_config`` the left glove's
    glove file (empty: the right glove's)."""

    right: str = ""
    left: str = ""
    left_config: str = ""


@dataclass(frozen=True)
class RigConfig:
    """The whole rig file: ``[bus]``, ``[loop]``, ``[silence]``, ``[heat]``,
    ``[calibration]``, ``[[servos]]``, and for two hands ``[gloves]`` and ``[left_bus]``
    (the left hand's servos on a bus of their own; without it both hands share
    ``[bus]``)."""

    bus: BusConfig = BusConfig()
    loop: LoopConfig = LoopConfig()
    servos: tuple[ServoCalibration, ...] = ()
    servo_settings: ServoSettings = ServoSettings()
    silence: SilenceConfig = SilenceConfig()
    heat: HeatConfig = HeatConfig()
    calibration: CalibrationConfig = CalibrationConfig()
    gloves: GlovesConfig = GlovesConfig()
    left_bus: BusConfig | None = None

    def check(self) -> None:
        if not self.servos:
            raise ConfigError(
                "no [[servos]]: the rig drives no servo", key="servos",
                allowed="one [[servos]] table per servo (id, joint, zero_ticks, limits);"
                " see config/rig.toml")
        seen_ids: dict[int, int] = {}
        seen_joints: dict[str, int] = {}
        for i, s in enumerate(self.servos):
            if s.id in seen_ids:
                raise ConfigError(
                    f"servo ID used twice (also servos[{seen_ids[s.id]}])",
                    key=f"servos[{i}].id", value=s.id,
                )
            if s.joint in seen_joints:
                raise ConfigError(
                    f"joint driven twice (also servos[{seen_joints[s.joint]}])",
                    key=f"servos[{i}].joint", value=s.joint,
                )
            seen_ids[s.id] = i
            seen_joints[s.joint] = i
        if self.left_bus is not None and not any(s.joint.startswith("le")
                                                 for s in self.servos):
            raise ConfigError("[left_bus] is given but no servo drives a left-hand joint",
                              key="left_bus", allowed="left-hand servos (joints le...) in "
                              "[[servos]], or no [left_bus]")
        check_servo_settings(self)

    def servo(self, servo_id: int) -> ServoCalibration:
        for s in self.servos:
            if s.id == servo_id:
                return s
        raise KeyError(servo_id)

    @property
    def effective_sag_gain(self) -> float:
        """The sag gain the pipeline uses ([loop].sag_gain; a robot rig turns it off
        unless its ``[robot].sag`` is true, see :mod:`handrig.pose.robot_rig`)."""
        return self.loop.sag_gain


HAND_NAMES = {"ri": "right", "le": "left"}


def hand_of_joint(joint: str) -> str:
    """``"ri"`` or ``"le"``: the hand a servo's joint belongs to (by its prefix)."""
    return "le" if joint.startswith("le") else "ri"


def hand_rig(rig: RigConfig, hand: str) -> RigConfig:
    """One hand's part of a rig: that hand's servos (joints ``ri...`` or ``le...``) on
    that hand's bus (``[left_bus]`` for the left hand when the rig has one, else
    ``[bus]``). ConfigError when the rig drives no servo of that hand."""
    if hand not in HAND_NAMES:
        raise ConfigError("unknown hand", key="hand", value=hand, allowed="ri or le")
    servos = tuple(s for s in rig.servos if hand_of_joint(s.joint) == hand)
    if not servos:
        raise ConfigError(f"the rig drives no servo of the {HAND_NAMES[hand]} hand",
                          key="servos", allowed=f"[[servos]] with joints {hand}...")
    bus = rig.left_bus if hand == "le" and rig.left_bus is not None else rig.bus
    return dataclasses.replace(rig, servos=servos, bus=bus, left_bus=None)


def load_rig_config(path: str | Path | None = None) -> RigConfig:
    """Load the rig file ``path``; None: the default rig file, the one a run without
    ``--rig`` reads (:func:`handrig.config.rig_files.resolve_rig_file`'s one rule:
    your ``rig.toml``, else the shipped one). A bench or test that wants the fixed
    shipped rig whatever is in your home names it
    (:data:`handrig.config.rig_files.SHIPPED_RIG`)."""
    return load(path or resolve_rig_file(None).path, RigConfig)
