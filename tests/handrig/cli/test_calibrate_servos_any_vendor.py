"""``handrig calibrate servos``'s dialogue on a servo of another vendor: a toy
:class:`ZeroingBus` with 1000 raw positions a turn and a travel of 0..999, so every
figure the dialogue shows or writes comes from the bus, none from the X series."""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Iterator

import pytest

from handrig.cli.calibrate_servos import calibrate
from handrig.clock import FakeClock
from handrig.config.rig import RigConfig, load_rig_config
from handrig.devices.servo.zeroing import ZeroingBus

PER_TURN = 1000
ZERO = 500


class ToyZeroing(ZeroingBus):
    """Servos that arrive at once where they are sent while torque is on."""

    def __init__(self, rig: RigConfig) -> None:
        self.rig = rig
        self.positions = [ZERO] * len(rig.servos)
        self.goals = list(self.positions)
        self.sent: list[tuple[int, int]] = []
        self.torque_on = False

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(s.id for s in self.rig.servos)

    def describe(self, index: int) -> str:
        return f"toy {self.ids[index]}"

    def connect(self) -> None:
        pass

    def close(self) -> None:
        self.torque_on = False

    @contextlib.contextmanager
    def _torque(self) -> Iterator[ToyZeroing]:
        self.goals = list(self.positions)
        self.torque_on = True
        try:
            yield self
        finally:
            self.torque_on = False

    def torque(self, *, handle_signals: bool = True
               ) -> contextlib.AbstractContextManager[ToyZeroing]:
        return self._torque()

    def relax(self) -> list[str]:
        self.torque_on = False
        return []

    def position(self, index: int) -> int:
        return self.positions[index]

    def goal(self, index: int) -> int:
        return self.goals[index]

    def send(self, index: int, position: int) -> None:
        low, high = self.travel
        assert low <= position <= high, f"sent {position}, outside the toy's travel"
        self.sent.append((index, position))
        self.goals[index] = position
        if self.torque_on:
            self.positions[index] = position

    @property
    def travel(self) -> tuple[int, int]:
        return 0, PER_TURN - 1

    def per_turn(self) -> float:
        return float(PER_TURN)


def toy_rig(ids: tuple[int, ...] = (7, 8)) -> RigConfig:
    """Servos 7 and 8 of the shipped rig (riIndexMCPy: -20..90 deg), zeros at the toy's."""
    rig = load_rig_config()
    return dataclasses.replace(rig, servos=tuple(
        dataclasses.replace(rig.servo(i), zero_ticks=ZERO) for i in ids))


def test_a_jog_moves_the_toy_by_its_own_positions_per_degree_and_the_reading_is_written(
) -> None:
    rig = toy_rig()
    bus = ToyZeroing(rig)
    prompts: list[str] = []
    answers = iter(["+9", "", "", "y", "s"])

    def ask(prompt: str) -> str:
        prompts.append(prompt)
        return next(answers)

    with bus.torque():
        changes = calibrate(bus, rig, [7, 8], jog=True, yes=False, ask=ask,
                            say=lambda _s: None, clock=FakeClock())
    jogged = round(ZERO + 9 * PER_TURN / 360)  # 525: 2.78 of the toy's positions a degree
    assert f"at {jogged} ticks (+9.0 deg" in prompts[1]
    assert changes == {7: {"zero_ticks": jogged}}
    # the direction check flexed the joint 10 deg from the new zero and came back
    assert "Did the joint flex" in prompts[3]
    assert bus.sent[1:] == [(0, round(jogged + 10 * PER_TURN / 360)), (0, jogged)]


def test_by_hand_a_flex_that_reads_negative_flips_the_toys_direction() -> None:
    rig = toy_rig()
    bus = ToyZeroing(rig)
    calls = 0

    def ask(prompt: str) -> str:
        nonlocal calls
        calls += 1
        if calls == 3:  # the person flexes the joint: -15 deg in the toy's positions
            bus.positions[0] = round(ZERO - 15 * PER_TURN / 360)
        return ["", "", "", "y"][calls - 1]

    bus.relax()
    changes = calibrate(bus, rig, [7], jog=False, yes=False, ask=ask, say=lambda _s: None,
                        clock=FakeClock())
    assert changes == {7: {"zero_ticks": ZERO, "direction": -1}}
    assert bus.sent == []  # by hand, nothing was sent to the servo


def test_a_zero_near_the_end_of_the_toys_travel_narrows_the_limits_to_it() -> None:
    rig = toy_rig()
    bus = ToyZeroing(rig)
    cal = rig.servo(7)  # -20..90 deg: -20 deg is 56 positions below the zero
    assert bus.propose(cal, 100, 20.0).limits_deg is None
    near = bus.propose(cal, 20, 20.0)
    assert near.limits_deg == (pytest.approx(-7.2), 90.0)
    assert near.shift_deg == pytest.approx(-480 * 360 / PER_TURN)
    assert "outside the servo's travel 0..999" in near.reasons[-1]
    high = bus.propose(cal, 990, 200.0)  # +90 deg needs 990 + 250: past 999
    assert high.limits_deg == (-20.0, pytest.approx(3.2))
    said: list[str] = []
    bus.positions[0] = 20
    changes = calibrate(bus, rig, [7], jog=False, yes=True, say=said.append, clock=FakeClock())
    assert changes == {}  # --yes does not confirm a narrowing
    assert any("not written (--yes does not confirm)" in s for s in said), said
