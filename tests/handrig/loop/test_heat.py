"""The [heat] tiers the loop applies to servos that warm up, on the real driver
(DynamixelBus over the in-process byte-level emulator, a FakeClock): the bus reads
the temperatures; the loop's HeatWatch warns, caps the hot servo's effort (Goal PWM,
which the emulator's physics applies), then acts, and lifts each tier as it cools."""

from __future__ import annotations

import re

import numpy as np
import pytest

from firmware_protocol.dynamixel import HardwareError
from firmware_protocol.dynamixel import Reg as SimReg
from handrig.config.rig import HeatConfig, SilenceConfig
from handrig.devices.servo import DynamixelBus
from handrig.errors import ServoFault
from handrig.loop.heat import CHECK_EVERY_S, HeatWatch
from handrig.loop.silence import SilenceWatch
from tests.helpers.servos import make_bus, small_rig

FULL_PWM = 885  # PWM Limit's initial value on every X-series model


def heat(action: str = "relax") -> HeatConfig:
    return HeatConfig(warn_c=50.0, act_c=55.0, action_c=60.0, relief_pwm_pct=40.0,
                      action=action)  # type: ignore[arg-type]


def at(peer: object, servo_id: int, temp_c: int) -> None:
    """The emulated servo's internal temperature (what Present Temperature reads)."""
    peer.servo(servo_id).warm_to(temp_c)  # type: ignore[attr-defined]


def read(bus: DynamixelBus, watch: HeatWatch) -> list[str]:
    bus.clock.advance(CHECK_EVERY_S)  # type: ignore[attr-defined]
    state = bus.read_state()
    assert np.isfinite(state.temperatures_c).all()  # temperature_every=1: read each time
    watch.update(state)
    return watch.drain_events()


def test_a_hot_servo_is_warned_capped_relaxes_the_rig_and_each_tier_ends_as_it_cools() -> None:
    bus, _, peer = make_bus(small_rig(), temperature_every=1)
    watch = HeatWatch(bus, heat("relax"))
    assert read(bus, watch) == []  # every servo at ambient
    at(peer, 3, 51)
    events = read(bus, watch)
    assert len(events) == 1 and events[0].startswith("servo 3 (riThumbCMCz) is at 51 C")
    assert "[heat] warn_c 50 C" in events[0]
    assert peer.servo(3).get(SimReg.GOAL_PWM) == FULL_PWM  # a warning only
    assert read(bus, watch) == []  # said once

    at(peer, 3, 56)
    events = read(bus, watch)
    assert len(events) == 1 and "servo 3 (riThumbCMCz) is at 56 C ([heat] act_c 55 C)" in events[0]
    assert "capped at 40 %" in events[0] and "the others go on" in events[0]
    assert peer.servo(3).get(SimReg.GOAL_PWM) == round(FULL_PWM * 0.4)
    assert peer.servo(3).effort_fraction() == pytest.approx(0.4, abs=0.001)
    assert all(peer.servo(i).get(SimReg.GOAL_PWM) == FULL_PWM for i in (1, 2, 4, 5, 6))
    assert watch.relax_reason is None

    at(peer, 3, 61)
    events = read(bus, watch)
    assert watch.relax_reason and "servo 3 (riThumbCMCz) is at 61 C" in watch.relax_reason
    assert any("relaxing every servo until it cools ([heat] action)" in e for e in events)

    at(peer, 3, 58)  # within the 3 K hysteresis of action_c: nothing changes
    assert read(bus, watch) == [] and watch.relax_reason is not None
    at(peer, 3, 56)
    events = read(bus, watch)
    assert watch.relax_reason is None
    assert events == ["servo 3 (riThumbCMCz) cooled to 56 C, below [heat] action_c 60 C"]
    assert peer.servo(3).get(SimReg.GOAL_PWM) == round(FULL_PWM * 0.4)  # still capped

    at(peer, 3, 51)
    events = read(bus, watch)
    assert events == ["servo 3 (riThumbCMCz) cooled to 51 C: its full effort is back, easing "
                      "its joint back to its goals from where it is"]
    assert watch.uncapped == [2]
    assert peer.servo(3).get(SimReg.GOAL_PWM) == FULL_PWM
    at(peer, 3, 40)
    assert read(bus, watch) == [
        "servo 3 (riThumbCMCz) cooled to 40 C, below [heat] warn_c 50 C"]
    assert (watch.warnings, watch.reliefs, watch.actions) == (1, 1, 1)
    assert watch.max_c[2] == 61 and watch.hottest() == "servo 3 (riThumbCMCz) 61 C"


def test_stop_ends_the_run_naming_the_servo_before_its_own_limit() -> None:
    bus, _, peer = make_bus(small_rig(), temperature_every=1)
    watch = HeatWatch(bus, heat("stop"))
    at(peer, 5, 62)  # all three tiers at once: warned, capped, then stopped
    with pytest.raises(ServoFault) as err:
        read(bus, watch)
    text = str(err.value)
    assert re.search(r"servo 5 \(riThumbIPz\) is at 62 C \(\[heat\] action_c 60 C\)", text)
    assert "[heat] action is stop" in text
    assert peer.servo(5).get(SimReg.GOAL_PWM) == round(FULL_PWM * 0.4)  # capped first
    events = watch.drain_events()
    assert any("warn_c" in e for e in events) and any("capped at 40 %" in e for e in events)


def test_continue_keeps_the_cap_and_asks_no_relax() -> None:
    bus, _, peer = make_bus(small_rig(), temperature_every=1)
    watch = HeatWatch(bus, heat("continue"))
    at(peer, 2, 65)
    events = read(bus, watch)
    assert watch.relax_reason is None
    assert any("going on with its effort capped ([heat] action continue)" in e for e in events)
    assert peer.servo(2).get(SimReg.GOAL_PWM) == round(FULL_PWM * 0.4)


def test_a_capped_servo_that_is_rebooted_is_capped_again() -> None:
    bus, _, peer = make_bus(small_rig(), temperature_every=1)
    watch = HeatWatch(bus, heat("continue"))
    with bus.torque(handle_signals=False):
        at(peer, 4, 57)
        read(bus, watch)
        assert peer.servo(4).get(SimReg.GOAL_PWM) == round(FULL_PWM * 0.4)
        peer.servo(4).inject_hardware_error(HardwareError.OVERLOAD)
        for _ in range(20):  # the driver sees the Alert bit, reboots the servo
            bus.clock.advance(0.01)  # type: ignore[attr-defined]
            bus.write_goals_deg(np.zeros(6))
            state = bus.read_state()
            watch.update(state)
            if state.stats.reboots.sum():
                break
        assert bus.stats.reboots.sum() == 1
        events = watch.drain_events() + read(bus, watch)
        assert peer.servo(4).get(SimReg.GOAL_PWM) == round(FULL_PWM * 0.4)
        assert "servo 4 (riThumbMCPz) was rebooted: its effort is capped at 40 % again" \
            in events


def test_goal_pwm_above_the_pwm_limit_is_refused_by_the_servo() -> None:
    bus, _, peer = make_bus(small_rig())
    with pytest.raises(ValueError, match=r"effort fraction must be in \(0, 1\]"):
        bus.limit_effort(0, 1.5)
    peer.servo(1).set(SimReg.PWM_LIMIT, 500)  # a rig that lowered PWM Limit (EEPROM)
    assert bus.limit_effort(0, 1.0)
    assert peer.servo(1).get(SimReg.GOAL_PWM) == 500  # full effort is the PWM Limit
    assert bus.limit_effort(0, 0.5) and peer.servo(1).get(SimReg.GOAL_PWM) == 250


def test_temperatures_are_read_about_once_a_second_at_the_shipped_read_rate() -> None:
    """The shipped rig reads present state 100 times a second (200 Hz, [bus] read_every
    2, in two parts); the driver's default sweep brings every servo's temperature
    about once a second (1.07 s here), far quicker than a servo warms (minutes)."""
    rig = small_rig()
    bus, _, peer = make_bus(rig)  # the driver's default temperature_every
    parts = rig.bus.read_parts
    clock = bus.clock
    seen_at: list[float] = []
    start = clock.now()
    temp = 40
    at(peer, 2, temp)
    k = 0
    while clock.now() - start < 4.5:
        state = bus.read_state(clock.now() + 0.008, (k % parts, parts))
        k += 1
        if state.temperatures_c[1] == temp:
            seen_at.append(clock.now() - start)
            temp += 1
            at(peer, 2, temp)
        clock.advance(0.01)  # type: ignore[attr-defined]
    gaps = np.diff([0.0, *seen_at])
    assert len(seen_at) >= 3, seen_at
    assert gaps.max() <= 1.5, gaps


def test_a_joint_given_its_effort_back_eases_to_its_goal_from_where_it_gave_way() -> None:
    bus, _, _ = make_bus(small_rig())
    silence = SilenceWatch(bus, SilenceConfig(), slew_deg_s=100.0)
    goals, sent = np.full(6, 10.0), np.full(6, 10.0)
    silence.ease_from(2, -30.0)  # the capped joint had sagged to -30 deg
    out = silence.steer(goals, sent, 0.01)
    assert out[2] == pytest.approx(-29.0)  # 100 deg/s x 10 ms from where it is
    assert np.all(np.delete(out, 2) == 10.0)
    for _ in range(60):
        sent = silence.steer(goals, sent, 0.01).copy()
    assert sent[2] == 10.0 and not silence.steering
