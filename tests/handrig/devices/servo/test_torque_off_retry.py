"""Torque-off asks a servo that did not confirm again after the others: a stall (of
the bus, or of an emulator on a busy host) that outlasts one servo's attempts is not
reported as a failed torque-off; a servo that stays silent still is, in bounded time.
Against the byte-level emulator through the real SDK port; what the servos got is read
from their own registers."""

from __future__ import annotations

import time

import pytest

from firmware_protocol.dynamixel import Reg as SimReg
from handrig.devices.servo import DynamixelBus
from handrig.devices.servo.torque import CONFIRM_ATTEMPTS, CONFIRM_BUDGET_S
from handrig.errors import TorqueOffError
from sim.dxl_bus import FaultSpec, SimBus
from tests.helpers.servos import small_rig

ATTEMPT_S = 0.05  # a command's reply timeout (handrig.devices.servo.link.COMMAND_TIMEOUT_S)


def test_a_servo_silent_for_longer_than_its_attempts_is_confirmed_on_a_later_round(
        sim: SimBus, bus: DynamixelBus) -> None:
    first = small_rig().servos[0].id
    # servo 1 is silent for more than its three attempts (150 ms) at the torque-off,
    # then answers again: the others are asked meanwhile, then servo 1 once more
    silent_s = CONFIRM_ATTEMPTS * ATTEMPT_S * 1.5
    with bus.torque(handle_signals=False):
        now = sim.uptime_s
        sim.faults = FaultSpec(mute=frozenset({first}), mute_from_s=now,
                               mute_until_s=now + 0.05 + silent_s)
    assert sim.fault_counts["muted replies"] >= CONFIRM_ATTEMPTS  # it did miss a round
    assert not any(sim.servo(s.id).torque_enabled for s in small_rig().servos)
    assert all(sim.servo(s.id).get(SimReg.BUS_WATCHDOG) == 0
               for s in small_rig().servos)


def test_a_servo_that_stays_silent_is_named_and_the_exit_stays_bounded(
        sim: SimBus, bus: DynamixelBus) -> None:
    first = small_rig().servos[0]
    started = float("nan")
    with (pytest.raises(TorqueOffError) as info, bus.torque(handle_signals=False)):
        sim.faults = FaultSpec(mute=frozenset({first.id}), mute_from_s=sim.uptime_s)
        started = time.monotonic()
    took = time.monotonic() - started
    text = str(info.value)
    assert f"servo {first.id} ({first.joint})" in text and "rounds)" in text
    assert not any(f"servo {s.id} ({s.joint})" in text for s in small_rig().servos[1:])
    # asked again after the others (three rounds of three attempts, fewer where a
    # loaded host used up the budget first), and the exit stayed within the budget
    assert 2 * CONFIRM_ATTEMPTS <= sim.fault_counts["muted replies"] <= 3 * CONFIRM_ATTEMPTS
    assert took < CONFIRM_BUDGET_S + 0.5, took
    assert not sim.servo(first.id).torque_enabled  # the broadcast reached it anyway
