"""Joint degrees <-> servo position ticks, the driver's side of a rig's calibration.

A rig file gives each servo a zero, a direction, a gear ratio and joint limits in
degrees (:class:`handrig.config.rig.ServoCalibration`, vendor-neutral data); what a
tick is belongs to the servos' driver. The X series count 4096 ticks per turn and
take goals in 0..4095 in position control mode (REFERENCE.md section 2)::

    ticks = zero_ticks + direction * deg * gear_ratio * 4096 / 360

:func:`check_positions` checks a rig's zeros and limits against that range (called
by :func:`handrig.devices.servo.models.check_rig`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from handrig.errors import ConfigError

TICKS_PER_TURN = 4096
TICKS_PER_DEG = TICKS_PER_TURN / 360.0
POSITION_TICKS_MIN = 0
POSITION_TICKS_MAX = 4095
SERVO_ID_MAX = 252  # IDs 253..255 are reserved by Protocol 2.0 (254: broadcast)


class Calibration(Protocol):
    """What the conversion reads of a rig servo (:class:`~handrig.config.rig.ServoCalibration`)."""

    @property
    def zero_ticks(self) -> int: ...
    @property
    def direction(self) -> int: ...
    @property
    def gear_ratio(self) -> float: ...
    @property
    def min_deg(self) -> float: ...
    @property
    def max_deg(self) -> float: ...


def deg_to_ticks_exact(cal: Calibration, deg: float) -> float:
    """Ticks for a joint angle in degrees, not rounded nor clamped."""
    return cal.zero_ticks + cal.direction * deg * cal.gear_ratio * TICKS_PER_DEG


def deg_to_ticks(cal: Calibration, deg: float) -> int:
    """Goal ticks for a joint angle, clamped to ``[min_deg, max_deg]`` first."""
    clamped = min(max(deg, cal.min_deg), cal.max_deg)
    return round(deg_to_ticks_exact(cal, clamped))


def ticks_to_deg(cal: Calibration, ticks: float) -> float:
    """Joint angle in degrees for a servo position in ticks (not clamped)."""
    return (ticks - cal.zero_ticks) / (cal.direction * cal.gear_ratio * TICKS_PER_DEG)


class RigServo(Calibration, Protocol):
    @property
    def id(self) -> int: ...


def check_positions(servos: Sequence[RigServo], file: str | None = None) -> None:
    """Each servo's ID in the bus's range, its zero in the position range and its joint
    limits mapping to ticks inside it. ConfigError naming ``servos[i].key``."""
    for i, s in enumerate(servos):
        if not 0 <= s.id <= SERVO_ID_MAX:
            raise ConfigError("servo ID out of range", file=file, key=f"servos[{i}].id",
                              value=s.id, allowed=f"0..{SERVO_ID_MAX}")
        if not POSITION_TICKS_MIN <= s.zero_ticks <= POSITION_TICKS_MAX:
            raise ConfigError("zero outside the position range", file=file,
                              key=f"servos[{i}].zero_ticks", value=s.zero_ticks,
                              allowed=f"{POSITION_TICKS_MIN}..{POSITION_TICKS_MAX}")
        for key, bound in (("min_deg", s.min_deg), ("max_deg", s.max_deg)):
            tick = deg_to_ticks_exact(s, bound)
            if not POSITION_TICKS_MIN <= tick <= POSITION_TICKS_MAX:
                raise ConfigError(
                    f"limit {bound} deg maps to {tick:.0f} ticks, outside the servo's range",
                    file=file, key=f"servos[{i}].{key}", value=bound,
                    allowed=f"limits whose ticks lie in {POSITION_TICKS_MIN}.."
                    f"{POSITION_TICKS_MAX}")
