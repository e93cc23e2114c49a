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
    send it somewhere, say what a reading means for its joint."""

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
    def move_to_deg(self, index: int, cal: ServoCalibration, deg: float) -> None:
        """Send servo ``index`` to joint angle ``deg`` of calibration ``cal`` (clamped
        into ``cal``'s limits)."""

    @abstractmethod
    def jog(self, index: int, cal: ServoCalibration, start: int, step_deg: float) -> None:
        """Move servo ``index`` by ``step_deg`` joint degrees from its last goal (jogs add
        up), never further than ``cal``'s span from raw position ``start`` nor outside
        the servo's travel."""

    @abstractmethod
    def joint_deg(self, cal: ServoCalibration, position: float) -> float:
        """Joint degrees of raw ``position`` under calibration ``cal`` (not clamped)."""

    @abstractmethod
    def propose(self, cal: ServoCalibration, position: int, max_shift_deg: float) -> Proposal:
        """What writing ``position`` as ``cal``'s zero would mean: its shift from the
        current zero (a confirmation above ``max_shift_deg``), and limits narrowed to
        what the servo can reach."""
