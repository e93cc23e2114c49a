"""The X-series servos as calibration talks to them
(:class:`~handrig.devices.servo.zeroing.ZeroingBus`): the Present Position and Goal
Position registers, 0..4095 ticks of travel, torque through
:class:`~handrig.devices.servo.dynamixel.DynamixelBus`.

A person answers the prompts between two moves, so the bus runs without its Bus
Watchdog (it would trip between two jogs and the servo would refuse the next goal),
and it holds a servo even outside the rig file's limits (the zero is what is being
found).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from handrig.config.rig import RigConfig, ServoCalibration
from handrig.devices.servo.dynamixel import DynamixelBus
from handrig.devices.servo.positions import (
    POSITION_TICKS_MAX,
    POSITION_TICKS_MIN,
    TICKS_PER_DEG,
    deg_to_ticks,
    deg_to_ticks_exact,
    ticks_to_deg,
)
from handrig.devices.servo.registers import Reg
from handrig.devices.servo.torque import TorqueContext
from handrig.devices.servo.zeroing import Proposal, ZeroingBus


def calibration_rig(rig: RigConfig) -> RigConfig:
    """The rig as calibration uses it: a person answers the prompts, so no Bus Watchdog
    (it would trip between two jogs and the servo would refuse the next goal)."""
    return dataclasses.replace(rig, bus=dataclasses.replace(rig.bus, watchdog_ms=0))


def propose(cal: ServoCalibration, ticks: int, max_shift_deg: float) -> Proposal:
    """What writing ``ticks`` as ``cal``'s zero would mean."""
    shift = ticks_to_deg(cal, ticks)  # joint degrees from the current zero
    reasons = []
    if abs(shift) > max_shift_deg:
        reasons.append(
            f"the zero moves {shift:+.1f} deg, more than [calibration] max_zero_shift_deg = "
            f"{max_shift_deg:g}: a joint hanging under gravity with torque off, or a horn "
            "mounted a spline off, reads like this")
    new = dataclasses.replace(cal, zero_ticks=ticks)
    ends = sorted((ticks_to_deg(new, POSITION_TICKS_MIN), ticks_to_deg(new, POSITION_TICKS_MAX)))
    low, high = max(cal.min_deg, ends[0]), min(cal.max_deg, ends[1])
    limits: tuple[float, float] | None = None
    if low > cal.min_deg or high < cal.max_deg:
        low, high = math.ceil(low * 10) / 10, math.floor(high * 10) / 10
        if low >= high:
            return Proposal(ticks, shift, tuple(reasons), None, impossible=(
                f"with zero_ticks {ticks} no part of [{cal.min_deg:g}, {cal.max_deg:g}] deg "
                "lies within the servo's 0..4095 ticks"))
        a, b = sorted((deg_to_ticks_exact(new, cal.min_deg), deg_to_ticks_exact(new, cal.max_deg)))
        reasons.append(
            f"with zero_ticks {ticks} the joint's range [{cal.min_deg:g}, {cal.max_deg:g}] deg "
            f"needs ticks {a:.0f}..{b:.0f}, outside the servo's travel 0..4095: accepting "
            f"narrows the limits to [{low:g}, {high:g}] deg")
        limits = (low, high)
    return Proposal(ticks, shift, tuple(reasons), limits)


class DynamixelZeroing(ZeroingBus):
    """Calibration's bus on ``port`` for the servos of ``rig`` (not yet connected)."""

    def __init__(self, port: str, rig: RigConfig) -> None:
        self.bus = DynamixelBus(port, calibration_rig(rig))
        self.bus.hold_outside_limits = True  # the zero is what is being found

    @property
    def ids(self) -> tuple[int, ...]:
        return self.bus.ids

    def describe(self, index: int) -> str:
        return self.bus.describe(index)

    def connect(self) -> None:
        self.bus.connect()

    def close(self) -> None:
        self.bus.close()

    def torque(self, *, handle_signals: bool = True) -> TorqueContext[Any]:
        return self.bus.torque(handle_signals=handle_signals)

    def relax(self) -> list[str]:
        return self.bus.disable_torque()

    def position(self, index: int) -> int:
        return self.bus.read_register(index, Reg.PRESENT_POSITION)

    def move_to_deg(self, index: int, cal: ServoCalibration, deg: float) -> None:
        self.bus.write_register(index, Reg.GOAL_POSITION, deg_to_ticks(cal, deg))

    def jog(self, index: int, cal: ServoCalibration, start: int, step_deg: float) -> None:
        span_deg = cal.max_deg - cal.min_deg
        ticks_per_deg = cal.direction * cal.gear_ratio * TICKS_PER_DEG
        base = self.bus.read_register(index, Reg.GOAL_POSITION)  # jogs add up
        goal = round(base + ticks_per_deg * step_deg)
        # never further from where it started than the joint's configured span
        span = abs(ticks_per_deg) * span_deg
        low, high = max(POSITION_TICKS_MIN, start - span), min(POSITION_TICKS_MAX, start + span)
        self.bus.write_register(index, Reg.GOAL_POSITION, int(min(max(goal, low), high)))

    def joint_deg(self, cal: ServoCalibration, position: float) -> float:
        return ticks_to_deg(cal, position)

    def propose(self, cal: ServoCalibration, position: int, max_shift_deg: float) -> Proposal:
        return propose(cal, position, max_shift_deg)
