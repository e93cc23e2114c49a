"""What bringing servos up needs of a vendor: the contract ``handrig servos`` and
``handrig setup`` talk to, whatever the servos' vendor.

Bring-up is the steps between unpacking servos and a first run: find what answers
on a port at which baud, give a servo an ID and a baud, reboot one, turn its torque
off, and compare the bus with a rig file. None of it is the realtime path: each step
opens the port, does its work and closes it again. A driver fills in
:class:`BusBringup` (its protocol, its bauds, its model names); the factory picks it
(:func:`handrig.app.factory.servo_bringup`), as it picks the session's
:class:`~handrig.devices.servo.bus.ServoBus` and calibration's
:class:`~handrig.devices.servo.zeroing.ZeroingBus`. The records here (a servo found,
a scan, a difference from the rig file) carry the vendor's facts already put into
words, so what is above prints them without knowing the vendor.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar

from handrig.config.rig import RigConfig


@dataclass(frozen=True)
class FoundServo:
    """A servo that answered: where, what it is (the vendor's number and its name), and
    its state (None: not read; ``unread`` names what did not answer)."""

    id: int
    baud: int
    model_number: int
    firmware: int
    model: str  # the vendor's name for ``model_number``
    operating_mode: int | None = None
    mode_name: str = "?"  # ``operating_mode`` in words, "?" when it was not read
    voltage_v: float | None = None
    temperature_c: int | None = None
    hardware_error: int | None = None  # the vendor's error bits, 0 none
    errors_text: str = "?"  # ``hardware_error`` in words, "?" when it was not read
    unread: tuple[str, ...] = ()  # what did not answer (those fields None)


@dataclass
class ScanResult:
    """What a scan found: the servos, and the bauds where replies collided."""

    servos: list[FoundServo] = field(default_factory=list)
    collisions: list[int] = field(default_factory=list)  # bauds with garbled replies
    tried: list[int] = field(default_factory=list)

    def ids_at(self, baud: int) -> list[int]:
        return sorted(s.id for s in self.servos if s.baud == baud)


@dataclass(frozen=True)
class Finding:
    """One difference between the bus and the rig file, with what to do about it."""

    servo_id: int
    what: str  # "missing", "extra", "model", "mode", "voltage", "hardware error", "unread"
    detail: str
    fix: str


class BusBringup(ABC):
    """Bring-up on one port: each method opens it at the baud it is given, does one
    step and closes it. DeviceError says what failed and what to do (no servo answers,
    an ID taken, replies garbled by two servos with one ID).

    The class attributes are known before a port is (the command line checks a
    ``--baud`` against :attr:`bauds`)."""

    bauds: ClassVar[tuple[int, ...]]
    """Every baud the vendor's servos take, slowest first."""
    family: ClassVar[str]
    """How messages name the servos, e.g. ``"the X series"`` (``"a baud {family}
    supports"``)."""
    one_at_a_time: ClassVar[str]
    """What to do when replies collide (two servos with one ID answering together)."""

    def __init__(self, port: str) -> None:
        self.port = port

    @abstractmethod
    def scan(self, bauds: Sequence[int]) -> ScanResult:
        """Every servo that answers at each of ``bauds``, described (:class:`FoundServo`),
        and the bauds where replies collided."""

    @abstractmethod
    def ping_all(self, baud: int) -> tuple[dict[int, int], bool]:
        """``({id: model number}, collided)``: who answers at ``baud`` (not described)."""

    @abstractmethod
    def ping(self, baud: int, servo_id: int) -> int | None:
        """The model number of the servo answering as ``servo_id`` at ``baud`` (asked a
        few times: one lost reply is not an absence), None if none does."""

    @abstractmethod
    def search_order(self, first: Sequence[int] = ()) -> list[int]:
        """The bauds to look for a servo at, in order: ``first`` (the rig's), the
        factory's, then the others, the slow ones last."""

    @abstractmethod
    def find_baud(self, servo_id: int, bauds: Sequence[int]) -> int:
        """The first of ``bauds`` at which a servo answers as ``servo_id``; DeviceError
        naming what was tried when none does."""

    @abstractmethod
    def set_id(self, baud: int, old_id: int, new_id: int) -> list[str]:
        """Give the servo answering as ``old_id`` at ``baud`` the ID ``new_id`` (refused
        when ``new_id`` is taken); what was done, a line each."""

    @abstractmethod
    def set_baud(self, baud: int, servo_id: int, new_baud: int) -> list[str]:
        """Move servo ``servo_id`` from ``baud`` to ``new_baud`` (refused when its ID is
        taken there); what was done, a line each."""

    @abstractmethod
    def reboot(self, baud: int, servo_id: int) -> FoundServo:
        """Reboot servo ``servo_id`` (clears an error whose cause is gone); its state
        afterwards."""

    @abstractmethod
    def torque_off(self, baud: int, servo_id: int) -> bool:
        """Turn servo ``servo_id``'s torque off; whether it had been on."""

    @abstractmethod
    def check(self, rig: RigConfig, *, baud: int | None = None
              ) -> tuple[list[FoundServo], list[Finding]]:
        """The servos answering at ``baud`` (None: the rig's) and how they differ from
        ``rig``: missing, extra, another model or mode, errors, each with its fix."""

    @abstractmethod
    def model_name(self, model_number: int) -> str:
        """The vendor's name for ``model_number`` (``"model N"`` for one it does not
        know)."""
