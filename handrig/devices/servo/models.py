"""The X-series servos the driver knows, as data, and the rig checked against them.

Model numbers, the bauds the servos and dynamixel-sdk both accept, each model's
Temperature Limit, Current Limit and current unit (REFERENCE.md section 2; ROBOTIS
e-manual control tables). A rig file names a servo's
model as a string (``model = "XL330-M288"``; empty: :data:`DEFAULT_MODEL`); what the
model means is this module's: :func:`check_rig` checks a rig against it (the factory
before it opens the bus, the driver when it is built), so nothing above
``handrig/devices/servo/`` holds a model table.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from handrig.config.rig import RigConfig, ServoSettings
from handrig.devices.servo.positions import check_positions
from handrig.devices.servo.registers import (
    OPERATING_MODE_CURRENT_BASED_POSITION,
    OPERATING_MODE_EXTENDED_POSITION,
    OPERATING_MODE_POSITION,
)
from handrig.errors import ConfigError

DEFAULT_MODEL = "XL330-M288"  # a servo whose rig file names no model
# Model numbers of the X-series servos we know (REFERENCE.md section 2).
MODEL_NUMBERS: dict[str, int] = {"XL330-M288": 1200, "XC330-T288": 1220, "XM430-W350": 1020}
MODEL_NUMBERS["XC330-M288"] = 1240  # the LEAP hand's servo
MODEL_NUMBERS["XL330-M077"] = 1190
MODEL_NUMBERS["XC430-W150"] = 1070  # no current sensing (e-manual): no current limit
MODEL_NUMBERS["XC430-T240BB"] = 1080  # ORCA's wrist; no current sensing either
MODEL_NAMES: dict[int, str] = {number: name for name, number in MODEL_NUMBERS.items()}
# Baud rates the X series and dynamixel-sdk both accept.
BAUD_RATES: tuple[int, ...] = (9600, 57600, 115200, 1_000_000, 2_000_000, 3_000_000, 4_000_000)
# Temperature Limit (31) initial value per model, deg C: the servo turns its torque off
# above it (e-manual control tables: X330 70, X430 80).
TEMPERATURE_LIMIT_C: dict[str, int] = {
    "XL330-M288": 70, "XL330-M077": 70, "XC330-M288": 70, "XC330-T288": 70,
    "XM430-W350": 80, "XC430-W150": 80, "XC430-T240BB": 80,
}
# Current Limit (38) maximum per model, mA: XL330-M288 1750 x 1 mA, XC330-T288 910 x 1 mA,
# XC330-M288 2352 x 1 mA, XM430-W350 1193 x 2.69 mA (ROBOTIS e-manual control tables).
# XL330-M077 1750 x 1 mA. Models absent here (the XC430s) have no Current Limit.
CURRENT_LIMIT_MAX_MA: dict[str, float] = {
    "XL330-M288": 1750.0, "XC330-T288": 910.0, "XC330-M288": 2352.0, "XM430-W350": 1193 * 2.69,
    "XL330-M077": 1750.0,
}
CURRENT_UNIT_MA: dict[str, float] = {
    "XL330-M288": 1.0, "XC330-T288": 1.0, "XC330-M288": 1.0, "XM430-W350": 2.69,
    "XL330-M077": 1.0,
}
# Stall torque (N m) and stall current (A) at the recommended supply, and Position P
# Gain's (84) initial value, per model (ROBOTIS e-manual: each model's specifications
# and control table). The XC430s have no current sensing: their torque is not capped.
STALL_TORQUE_NM: dict[str, float] = {
    "XL330-M288": 0.52, "XL330-M077": 0.215, "XC330-M288": 0.93, "XC330-T288": 0.92,
    "XM430-W350": 4.1, "XC430-W150": 1.6, "XC430-T240BB": 1.9,
}
STALL_CURRENT_A: dict[str, float] = {
    "XL330-M288": 1.47, "XL330-M077": 1.47, "XC330-M288": 1.80, "XC330-T288": 0.80,
    "XM430-W350": 2.3, "XC430-W150": 1.4, "XC430-T240BB": 1.4,
}
POSITION_P_GAIN_DEFAULT: dict[str, int] = {
    "XL330-M288": 400, "XL330-M077": 400, "XC330-M288": 1100, "XC330-T288": 900,
    "XM430-W350": 800, "XC430-W150": 460, "XC430-T240BB": 700,
}
PWM_LIMIT = 885  # PWM Limit (36) initial value: 100 % duty
RETURN_DELAY_UNIT_US = 2  # Return Delay Time (9) counts 2 us, 0..254
RETURN_DELAY_MAX_US = 254 * RETURN_DELAY_UNIT_US
GAIN_MAX = 16383  # Position P/I/D Gain range 0..16383
# Operating Mode (11) values of the modes a rig may name (REFERENCE.md section 2).
OPERATING_MODES: dict[str, int] = {
    "position": OPERATING_MODE_POSITION,
    "extended_position": OPERATING_MODE_EXTENDED_POSITION,
    "current_based_position": OPERATING_MODE_CURRENT_BASED_POSITION,
}


@dataclass(frozen=True)
class ResolvedServoSettings:
    """The settings of one servo, groups applied (what commissioning writes and checks)."""

    servo_id: int
    operating_mode: int  # Operating Mode (11) value
    current_limit_ma: int | None
    position_p_gain: int | None
    position_d_gain: int | None
    return_delay_us: int


def resolve_servo_settings(settings: ServoSettings, servo_id: int) -> ResolvedServoSettings:
    """``[servo_settings]`` for one servo, with its group's values where it has one."""
    current, p_gain, d_gain = (settings.current_limit_ma, settings.position_p_gain,
                               settings.position_d_gain)
    for group in settings.groups:
        if servo_id in group.ids:
            current = group.current_limit_ma if group.current_limit_ma is not None else current
            p_gain = group.position_p_gain if group.position_p_gain is not None else p_gain
            d_gain = group.position_d_gain if group.position_d_gain is not None else d_gain
    return ResolvedServoSettings(servo_id, OPERATING_MODES[settings.mode_for(servo_id)],
                                 current, p_gain, d_gain, settings.return_delay_us)


def servo_settings_for(rig: RigConfig, servo_id: int) -> ResolvedServoSettings:
    """What commissioning writes to servo ``servo_id`` of ``rig`` ([servo_settings],
    groups applied)."""
    return resolve_servo_settings(rig.servo_settings, servo_id)


class HasModel(Protocol):
    @property
    def model(self) -> str: ...


def servo_model(servo: HasModel) -> str:
    """A rig servo's model name (the rig file's, else :data:`DEFAULT_MODEL`)."""
    return servo.model or DEFAULT_MODEL


def current_limit_units(current_limit_ma: int | None, model: str) -> int | None:
    """Current Limit / Goal Current in the register's units for servo ``model`` (None:
    none set, or a model without current sensing)."""
    if current_limit_ma is None or model not in CURRENT_UNIT_MA:
        return None
    return round(current_limit_ma / CURRENT_UNIT_MA[model])


def temperature_limit_c(servo: HasModel) -> float:
    """The servo's own Temperature Limit, deg C (NaN for a model not in the table)."""
    return float(TEMPERATURE_LIMIT_C.get(servo_model(servo), float("nan")))


def check_rig(rig: RigConfig, file: str | None = None) -> None:
    """The rig against the servos it names: a known model each, bauds they accept,
    ``[heat] action_c`` below each one's Temperature Limit, current limits within each
    model's and current-based position only on models that sense current.
    ConfigError naming the key (and ``file`` when given)."""
    check_positions(rig.servos, file)
    for key, bus in (("bus", rig.bus), ("left_bus", rig.left_bus)):
        if bus is not None and bus.baud not in BAUD_RATES:
            raise ConfigError("unsupported baud rate", file=file, key=f"{key}.baud",
                              value=bus.baud, allowed=", ".join(str(b) for b in BAUD_RATES))
    for i, s in enumerate(rig.servos):
        model = servo_model(s)
        if model not in MODEL_NUMBERS:
            raise ConfigError("unknown servo model", file=file, key=f"servos[{i}].model",
                              value=s.model, allowed=", ".join(MODEL_NUMBERS))
        limit = TEMPERATURE_LIMIT_C.get(model)
        if limit is not None and rig.heat.action_c >= limit:
            raise ConfigError(
                f"[heat] action_c is not below servo {s.id}'s ({model}) Temperature "
                f"Limit of {limit} C, where it turns its torque off by itself",
                file=file, key="heat.action_c", value=rig.heat.action_c,
                allowed=f"below {limit} C")
    _check_settings(rig, rig.servo_settings, file)


def _check_registers(settings: ServoSettings, file: str | None) -> None:
    tables = [("servo_settings", settings.position_p_gain, settings.position_d_gain)] + [
        (f"servo_settings.groups[{g}]", group.position_p_gain, group.position_d_gain)
        for g, group in enumerate(settings.groups)]
    for where, p_gain, d_gain in tables:
        for key, value in (("position_p_gain", p_gain), ("position_d_gain", d_gain)):
            if value is not None and not 0 <= value <= GAIN_MAX:
                raise ConfigError("gain out of range", file=file, key=f"{where}.{key}",
                                  value=value, allowed=f"0..{GAIN_MAX}")
    delay = settings.return_delay_us
    if not 0 <= delay <= RETURN_DELAY_MAX_US or delay % RETURN_DELAY_UNIT_US:
        raise ConfigError("return delay out of range", file=file,
                          key="servo_settings.return_delay_us", value=delay,
                          allowed=f"0..{RETURN_DELAY_MAX_US} us in steps of "
                          f"{RETURN_DELAY_UNIT_US} (0 is what a fast loop wants)")


def _check_settings(rig: RigConfig, settings: ServoSettings, file: str | None) -> None:
    _check_registers(settings, file)
    top_any = max(CURRENT_LIMIT_MAX_MA.values())
    for key, value in [("servo_settings.current_limit_ma", settings.current_limit_ma)] + [
            (f"servo_settings.groups[{g}].current_limit_ma", group.current_limit_ma)
            for g, group in enumerate(settings.groups)]:
        if value is not None and value > top_any:
            raise ConfigError("current limit out of range", file=file, key=key, value=value,
                              allowed=f"1..{top_any:.0f} mA (and at most the servo model's "
                              "own maximum)")
    for s in rig.servos:
        model = servo_model(s)
        resolved = resolve_servo_settings(settings, s.id)
        if model not in CURRENT_LIMIT_MAX_MA:  # no current sensing: nothing to check
            if resolved.operating_mode == OPERATING_MODES["current_based_position"]:
                raise ConfigError(f"servo {s.id} ({model}) has no current-based position "
                                  "mode", file=file, key="servo_settings.operating_mode",
                                  allowed="a group with operating_mode = \"position\" or "
                                  "\"extended_position\" for it")
            continue
        top = CURRENT_LIMIT_MAX_MA[model]
        if resolved.current_limit_ma is not None and resolved.current_limit_ma > top:
            raise ConfigError(f"current limit above the {model}'s maximum for servo {s.id}",
                              file=file, key="servo_settings.current_limit_ma",
                              value=resolved.current_limit_ma, allowed=f"1..{top:.0f} mA")


def holding_stiffness_nm_per_rad(servo: HasModel, position_p_gain: int | None) -> float:
    """How hard a servo at rest pushes back per radian its horn is off its goal, N m/rad.

    The e-manual's position controller turns the error in pulses into PWM through
    KPP = Position P Gain / 128 (PWM in units of :data:`PWM_LIMIT` = 100 %); at a
    standstill the motor's torque follows its duty, the stall torque at 100 %. None:
    the model's initial P gain.
    """
    model = servo_model(servo)
    p_gain = POSITION_P_GAIN_DEFAULT[model] if position_p_gain is None else position_p_gain
    pulses_per_rad = 4096 / (2 * 3.141592653589793)
    return STALL_TORQUE_NM[model] * (p_gain / 128.0) / PWM_LIMIT * pulses_per_rad


def torque_cap_nm(servo: HasModel, current_limit_ma: int | None) -> float:
    """The most torque a servo gives at its horn, N m: its stall torque, scaled by its
    current cap over its stall current where it has one (current sensing, a limit)."""
    model = servo_model(servo)
    stall = STALL_TORQUE_NM[model]
    if current_limit_ma is None or model not in CURRENT_LIMIT_MAX_MA:
        return stall
    return stall * min(1.0, current_limit_ma / 1000.0 / STALL_CURRENT_A[model])
