"""Emulated servos for a rig config: IDs, models, start positions, goal limits.

A robot hand (LEAP, ORCA) is a rig config like any other: nothing here is
special to one.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

from firmware_protocol.dynamixel import MODELS
from handrig.config.rig import RigConfig
from handrig.devices.servo.models import DEFAULT_MODEL, servo_model
from handrig.devices.servo.positions import check_positions, deg_to_ticks
from handrig.errors import ConfigError
from sim.dxl_servo import EmulatedServo


def with_model(config: RigConfig, model: str) -> RigConfig:
    """The rig with every servo of model ``model`` (servos and puppet must agree)."""
    if model not in MODELS:
        raise ConfigError("unknown servo model", key="model", value=model,
                          allowed=", ".join(MODELS))
    return dataclasses.replace(config, servos=tuple(
        dataclasses.replace(s, model=model) for s in config.servos))


GOAL_POSITION_ADDRESS = 116  # Goal Position (REFERENCE.md section 2)


def goal_limits(config: RigConfig) -> dict[int, tuple[int, int]]:
    """Each calibrated servo's ``[min_deg, max_deg]`` as (lowest, highest) goal ticks."""
    out = {}
    for s in config.servos:
        a, b = deg_to_ticks(s, s.min_deg), deg_to_ticks(s, s.max_deg)
        out[s.id] = (min(a, b), max(a, b))
    return out


def servos_from_rig(
    config: RigConfig, *, ids: Sequence[int] | None = None, model: str | None = None,
    bauds: Mapping[int, int] | None = None,
) -> list[EmulatedServo]:
    """Emulated servos for a rig: its IDs (or ``ids``), its models (or ``model``),
    each starting at its calibrated zero (joint at 0 deg), each at the rig's baud or
    the one ``bauds`` gives its ID (bits per second)."""
    check_positions(config.servos)  # zeros and limits the emulated servos can hold
    bauds = bauds or {}
    unknown = sorted(set(bauds) - set(ids if ids is not None else
                                      [s.id for s in config.servos]))
    if unknown:
        raise ConfigError("a baud is given for a servo that is not on the bus",
                          key="servo baud", value=unknown)
    calibrated = {s.id: s for s in config.servos}
    wanted = list(ids) if ids is not None else list(calibrated)
    out = []
    for servo_id in wanted:
        cal = calibrated.get(servo_id)
        out.append(EmulatedServo(
            servo_id,
            model or (servo_model(cal) if cal else DEFAULT_MODEL),
            baud=bauds.get(servo_id, config.bus.baud),
            start_ticks=float(cal.zero_ticks) if cal else 2048.0,
        ))
    return out
