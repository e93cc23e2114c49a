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
from typing import Any

from handrig.config.rig import RigConfig
from handrig.devices.servo.dynamixel import DynamixelBus
from handrig.devices.servo.positions import POSITION_TICKS_MAX, POSITION_TICKS_MIN, TICKS_PER_TURN
from handrig.devices.servo.registers import Reg
from handrig.devices.servo.torque import TorqueContext
from handrig.devices.servo.zeroing import ZeroingBus


def calibration_rig(rig: RigConfig) -> RigConfig:
    """The rig as calibration uses it: a person answers the prompts, so no Bus Watchdog
    (it would trip between two jogs and the servo would refuse the next goal)."""
    return dataclasses.replace(rig, bus=dataclasses.replace(rig.bus, watchdog_ms=0))


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

    def goal(self, index: int) -> int:
        return self.bus.read_register(index, Reg.GOAL_POSITION)

    def send(self, index: int, position: int) -> None:
        self.bus.write_register(index, Reg.GOAL_POSITION, position)

    @property
    def travel(self) -> tuple[int, int]:
        return POSITION_TICKS_MIN, POSITION_TICKS_MAX

    def per_turn(self) -> float:
        return float(TICKS_PER_TURN)
