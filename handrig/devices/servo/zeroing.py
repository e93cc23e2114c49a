"""What finding each servo's zero needs of a bus: the contract ``handrig calibrate
servos`` talks to, whatever the servos' vendor.

Positions here are the servo's own raw position, the unit of a rig file's
``zero_ticks``; what one is worth in joint degrees, and how far a servo can turn,
belong to the driver that implements this contract. A driver opens one through the
factory (:func:`handrig.app.factory.zeroing_bus`), like the session's
:class:`~handrig.devices.servo.bus.ServoBus`. Torque stays off unless the caller
holds :meth:`ZeroingBus.torque`; the bus holds a servo wherever it is sent, even
outside the rig file's limits (the zero is what is being found).
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Any

from handrig.config.rig import ServoCalibration


@dataclass(frozen=True)
class Proposal:
    """A reading as a new zero: its shift, what needs a confirmation, the new limits."""

    zero_ticks: int
    shift_deg: float
    reasons: tuple[str, ...]  # why a typed confirmation is needed (empty: none)
    limits_deg: tuple[float, float] | None  # narrowed limits, None when they fit
    impossible: str = ""  # why this zero cannot be used at all


class ZeroingBus(ABC):
    """A bus of servos, in rig order, as calibration uses it: read where a servo is,
    send it somewhere, say what a reading means for its joint.

    A driver fills in the abstract methods (its registers, its travel, its raw
    positions per turn); what a reading means under a rig file's calibration, jogs and
    a new zero's proposal follow from them here, the same for every vendor."""

    @property
    @abstractmethod
    def ids(self) -> tuple[int, ...]:
        """Each servo's bus id, in rig order."""

    @abstractmethod
    def describe(self, index: int) -> str:
        """``"servo 7 (riRingPIPy)"`` for the servo at rig index ``index``."""

    @abstractmethod
    def connect(self) -> None:
        """Open the port and commission every servo; DeviceError says what is wrong."""

    @abstractmethod
    def close(self) -> None:
        """Torque off if still on, close the port. Safe to call twice."""

    @abstractmethod
    def torque(self, *, handle_signals: bool = True) -> AbstractContextManager[Any]:
        """Context manager: torque on inside (each servo held where it is), off on every
        way out."""

    @abstractmethod
    def relax(self) -> list[str]:
        """Torque off on every servo, so a person can move the joints; returns the servos
        that did not confirm it."""

    @abstractmethod
    def position(self, index: int) -> int:
        """Present raw position of servo ``index`` (the unit of ``zero_ticks``)."""

    @abstractmethod
    def goal(self, index: int) -> int:
        """The raw position servo ``index`` was last sent to (its goal)."""

    @abstractmethod
    def send(self, index: int, position: int) -> None:
        """Send servo ``index`` to raw ``position`` (inside :attr:`travel`)."""

    @property
    @abstractmethod
    def travel(self) -> tuple[int, int]:
        """The raw positions a servo can be sent to, lowest and highest."""

    @abstractmethod
    def per_turn(self) -> float:
        """Raw positions in one turn of a servo's output shaft."""

    # -- what a reading means: the rig file's calibration in the driver's units -----------
    def per_joint_deg(self, cal: ServoCalibration) -> float:
        """Raw positions per joint degree under ``cal`` (signed: its direction)."""
        return cal.direction * cal.gear_ratio * self.per_turn() / 360.0

    def joint_deg(self, cal: ServoCalibration, position: float) -> float:
        """Joint degrees of raw ``position`` under calibration ``cal`` (not clamped)."""
        return (position - cal.zero_ticks) / self.per_joint_deg(cal)

    def position_of(self, cal: ServoCalibration, deg: float) -> float:
        """Raw position of joint angle ``deg`` under ``cal`` (not rounded nor clamped)."""
        return cal.zero_ticks + self.per_joint_deg(cal) * deg

    def move_to_deg(self, index: int, cal: ServoCalibration, deg: float) -> None:
        """Send servo ``index`` to joint angle ``deg`` of calibration ``cal`` (clamped
        into ``cal``'s limits)."""
        clamped = min(max(deg, cal.min_deg), cal.max_deg)
        self.send(index, round(self.position_of(cal, clamped)))

    def jog(self, index: int, cal: ServoCalibration, start: int, step_deg: float) -> None:
        """Move servo ``index`` by ``step_deg`` joint degrees from its last goal (jogs add
        up), never further than ``cal``'s span from raw position ``start`` nor outside
        the servo's travel."""
        per_deg = self.per_joint_deg(cal)
        goal = round(self.goal(index) + per_deg * step_deg)
        span = abs(per_deg) * (cal.max_deg - cal.min_deg)
        lowest, highest = self.travel
        low, high = max(lowest, start - span), min(highest, start + span)
        self.send(index, int(min(max(goal, low), high)))

    def propose(self, cal: ServoCalibration, position: int, max_shift_deg: float) -> Proposal:
        """What writing ``position`` as ``cal``'s zero would mean: its shift from the
        current zero (a confirmation above ``max_shift_deg``), and limits narrowed to
        what the servo's travel can reach."""
        shift = self.joint_deg(cal, position)  # joint degrees from the current zero
        reasons = []
        if abs(shift) > max_shift_deg:
            reasons.append(
                f"the zero moves {shift:+.1f} deg, more than [calibration] "
                f"max_zero_shift_deg = {max_shift_deg:g}: a joint hanging under gravity "
                "with torque off, or a horn mounted a spline off, reads like this")
        new = dataclasses.replace(cal, zero_ticks=position)
        lowest, highest = self.travel
        ends = sorted((self.joint_deg(new, lowest), self.joint_deg(new, highest)))
        low, high = max(cal.min_deg, ends[0]), min(cal.max_deg, ends[1])
        if low <= cal.min_deg and high >= cal.max_deg:
            return Proposal(position, shift, tuple(reasons), None)
        low, high = math.ceil(low * 10) / 10, math.floor(high * 10) / 10
        if low >= high:
            return Proposal(position, shift, tuple(reasons), None, impossible=(
                f"with zero_ticks {position} no part of [{cal.min_deg:g}, {cal.max_deg:g}] "
                f"deg lies within the servo's {lowest}..{highest} ticks"))
        a, b = sorted((self.position_of(new, cal.min_deg), self.position_of(new, cal.max_deg)))
        reasons.append(
            f"with zero_ticks {position} the joint's range [{cal.min_deg:g}, "
            f"{cal.max_deg:g}] deg needs ticks {a:.0f}..{b:.0f}, outside the servo's travel "
            f"{lowest}..{highest}: accepting narrows the limits to [{low:g}, {high:g}] deg")
        return Proposal(position, shift, tuple(reasons), (low, high))
