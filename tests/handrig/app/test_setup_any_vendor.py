"""``handrig setup``'s servo step on servos of another vendor: a toy :class:`BusBringup`
whose servos come as ID 0 at 250000 bps and whose model is called "toy-7", so every
baud, name and torque the wizard deals with comes from the contract, none from the
X series."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import pytest

from handrig.app.setup_wizard import Quit, commission_servos, find_new_servo
from handrig.config.rig import RigConfig, load_rig_config
from handrig.devices.servo.bringup import BusBringup, Finding, FoundServo, ScanResult
from handrig.errors import DeviceError

FACTORY_ID, FACTORY_BAUD, FAST = 0, 250_000, 2_500_000
TOY_MODEL = 7


@dataclasses.dataclass
class ToyServo:
    id: int = FACTORY_ID
    baud: int = FACTORY_BAUD
    torque: bool = True  # a toy servo comes holding


class ToyBringup(BusBringup):
    """Servos on a port, each answering only at its own baud."""

    bauds = (FACTORY_BAUD, FAST)
    family = "the toy series"
    one_at_a_time = "toys collide: plug in one at a time"

    def __init__(self, port: str, servos: list[ToyServo]) -> None:
        super().__init__(port)
        self.servos = servos
        self.calls: list[str] = []

    def _at(self, baud: int, servo_id: int) -> list[ToyServo]:
        return [s for s in self.servos if (s.id, s.baud) == (servo_id, baud)]

    def scan(self, bauds: Sequence[int]) -> ScanResult:
        raise AssertionError("the wizard does not scan")

    def ping_all(self, baud: int) -> tuple[dict[int, int], bool]:
        self.calls.append(f"ping_all {baud}")
        ids = [s.id for s in self.servos if s.baud == baud]
        return {i: TOY_MODEL for i in ids}, len(ids) != len(set(ids))

    def ping(self, baud: int, servo_id: int) -> int | None:
        return TOY_MODEL if self._at(baud, servo_id) else None

    def search_order(self, first: Sequence[int] = ()) -> list[int]:
        return list(dict.fromkeys([*first, FACTORY_BAUD, FAST]))

    def find_baud(self, servo_id: int, bauds: Sequence[int]) -> int:
        raise AssertionError("the wizard finds servos by ping_all")

    def set_id(self, baud: int, old_id: int, new_id: int) -> list[str]:
        (servo,) = self._at(baud, old_id)
        servo.id = new_id
        return [f"toy {old_id} is now {new_id}"]

    def set_baud(self, baud: int, servo_id: int, new_baud: int) -> list[str]:
        (servo,) = self._at(baud, servo_id)
        servo.baud = new_baud
        return [f"toy {servo_id} now at {new_baud}"]

    def reboot(self, baud: int, servo_id: int) -> FoundServo:
        raise AssertionError("the wizard reboots nothing")

    def torque_off(self, baud: int, servo_id: int) -> bool:
        (servo,) = self._at(baud, servo_id)
        was, servo.torque = servo.torque, False
        return was

    def check(self, rig: RigConfig, *, baud: int | None = None
              ) -> tuple[list[FoundServo], list[Finding]]:
        raise AssertionError("the command checks, not the wizard")

    def model_name(self, model_number: int) -> str:
        return f"toy-{model_number}"


def toy_rig() -> RigConfig:
    rig = load_rig_config()
    return dataclasses.replace(rig, servos=rig.servos[:2],
                               bus=dataclasses.replace(rig.bus, baud=FAST))


def test_the_wizard_readies_a_box_of_toy_servos_through_the_contract_alone() -> None:
    rig = toy_rig()
    first, second = ToyServo(), ToyServo()
    plugged: list[ToyServo] = []
    toys = ToyBringup("/dev/toy", plugged)
    lines: list[str] = []
    plug = iter([first, second])

    def ask(prompt: str) -> str:
        lines.append(prompt)
        plugged.append(next(plug))  # each prompt: the next new servo chained behind
        return ""

    done = commission_servos(toys, rig, [s.id for s in rig.servos], ask, lines.append)
    text = "\n".join(lines)
    assert done.ready == [1, 2] and not done.skipped, text
    assert [(s.id, s.baud, s.torque) for s in (first, second)] == [(1, FAST, False),
                                                                  (2, FAST, False)]
    assert f"found a toy-{TOY_MODEL} as ID 0 at {FACTORY_BAUD} bps" in text
    assert "toy 0 is now 1" in text and f"toy 1 now at {FAST}" in text
    assert f"servo 2 ready: ID 2 at {FAST} bps, torque off" in text
    # the search follows the vendor's order: the rig's baud first, then its factory's
    assert toys.calls[:2] == [f"ping_all {FAST}", f"ping_all {FACTORY_BAUD}"]


def test_a_toy_collision_says_the_vendors_advice_and_q_stops() -> None:
    toys = ToyBringup("/dev/toy", [ToyServo(), ToyServo()])
    with pytest.raises(DeviceError, match="toys collide: plug in one at a time"):
        find_new_servo(toys, [FACTORY_BAUD], {})
    lines: list[str] = []
    answers = iter(["", "q"])
    with pytest.raises(Quit):
        commission_servos(toys, toy_rig(), [1], lambda p: next(answers), lines.append)
    assert any("toys collide" in line for line in lines), lines
