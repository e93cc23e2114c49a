"""The [silence] tiers the loop applies to servos that stop answering, on the real driver
(DynamixelBus over the in-process byte-level emulator, a FakeClock): the bus reports
which servos answered and how old their readings are; the loop's SilenceWatch warns,
holds, then acts, and brings a servo that answers again back at the slew limit."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from handrig.config.rig import SilenceConfig
from handrig.devices.servo import DynamixelBus, FaultPolicy
from handrig.devices.servo.positions import deg_to_ticks
from handrig.errors import DeviceTimeoutError
from handrig.loop.silence import SilenceWatch
from tests.helpers.servos import make_bus, small_rig

RATE_HZ = 200.0  # the step a released servo takes is the slew limit over one write


def silence(action: str, warn_s: float = 0.1, hold_s: float = 0.2,
            action_s: float = 0.4) -> SilenceConfig:
    return SilenceConfig(warn_s=warn_s, hold_s=hold_s, action_s=action_s,
                         action=action)  # type: ignore[arg-type]


POLICY = FaultPolicy(read_budget_s=0.01)


class Loop:
    """What the loop does with a bus around each write and read (handrig.loop.cycle)."""

    def __init__(self, bus: DynamixelBus, config: SilenceConfig) -> None:
        self.bus = bus
        self.watch = SilenceWatch(bus, config, bus.rig.loop.slew_deg_s)
        self.sent = np.full(bus.n_servos, np.nan)

    def write(self, goals: np.ndarray) -> None:
        if self.watch.steering:
            goals = self.watch.steer(goals, self.sent, 1.0 / RATE_HZ)
        self.bus.write_goals_deg(goals)
        self.sent = self.bus.last_goals_deg

    def read(self):
        now = self.bus.clock.now()
        self.watch.note_read(now)
        state = self.bus.read_state()
        self.watch.update(state, self.bus.clock.now())
        return state

    def until(self, seconds: float, goals: np.ndarray, step_s: float = 0.02) -> None:
        """Goals and a read every ``step_s`` of fake time, for ``seconds``."""
        end = self.bus.clock.now() + seconds
        while self.bus.clock.now() < end:
            self.write(goals)
            self.read()
            self.bus.clock.advance(step_s)  # type: ignore[attr-defined]


def test_a_silent_servo_is_the_only_one_stale_then_warned_held_and_stopped() -> None:
    bus, _, peer = make_bus(small_rig(), fault_policy=POLICY)
    loop = Loop(bus, silence("stop"))
    first = loop.read()
    peer.servo(3).silent_until = math.inf
    for _ in range(2):
        state = loop.read()
        assert state.stale.tolist() == [False, False, True, False, False, False]
        assert state.answered.tolist() == [True, True, False, True, True, True]
        assert state.positions_deg[2] == first.positions_deg[2]
        assert not bus.last_read_whole
    assert bus.stats.timeouts > 0 and bus.stats.retries > 0
    with pytest.raises(DeviceTimeoutError) as err:
        loop.until(1.0, np.zeros(6))
    text = str(err.value)
    assert re.search(r"no valid reply from servo 3 \(riThumbCMCz\) for 0\.4\d s", text)
    assert "the other servos answer: check its cable, power and ID" in text
    assert "host was late" not in text
    events = loop.watch.drain_events()
    assert any(e.startswith("no valid reply from servo 3") for e in events)
    assert any(e.startswith("holding servo 3 (riThumbCMCz)") for e in events)
    assert loop.watch.silences == 1 and loop.watch.held == 1


def test_a_held_servo_keeps_its_goal_the_others_continue_and_it_comes_back_at_the_slew(
) -> None:
    rig = small_rig()
    bus, _, peer = make_bus(rig, fault_policy=POLICY)
    loop = Loop(bus, silence("continue"))
    with bus.torque(handle_signals=False):
        loop.write(np.zeros(6))
        peer.servo(3).silent_until = math.inf
        loop.until(0.3, np.zeros(6))  # past hold_s: servo 3 held at 0
        goals = np.full(6, 10.0)
        loop.until(0.4, goals)  # past action_s: continue
        sent = bus.last_goals_deg
        assert sent[2] == 0.0 and (np.delete(sent, 2) == 10.0).all()
        assert peer.servo(3).goal == deg_to_ticks(rig.servos[2], 0.0)
        events = loop.watch.drain_events()
        assert any("stays held, the others continue" in e for e in events)
        assert loop.watch.relax_reason is None
        peer.servo(3).silent_until = 0.0
        loop.read()
        assert loop.watch.recoveries == 1
        assert any("answers again after" in e and "releasing" in e
                   for e in loop.watch.drain_events())
        step = rig.loop.slew_deg_s / RATE_HZ
        loop.write(goals)
        assert bus.last_goals_deg[2] == pytest.approx(min(step, 10.0))
        for _ in range(int(10.0 / step) + 2):
            loop.write(goals)
        assert (bus.last_goals_deg == 10.0).all()
        assert not loop.watch.steering
        peer.servo(3).silent_until = math.inf
        loop.until(0.3, goals)
        assert loop.watch.steering
        peer.servo(3).silent_until = 0.0  # so that its torque-off is confirmed
    # the next run starts with a watch of its own: nothing held over
    assert not SilenceWatch(bus, silence("continue"), 720.0).steering


def test_relax_action_is_a_reason_until_the_servo_answers() -> None:
    bus, _, peer = make_bus(small_rig(), fault_policy=POLICY)
    loop = Loop(bus, silence("relax"))
    loop.read()
    peer.servo(5).silent_until = math.inf
    loop.until(0.5, np.zeros(6))
    reason = loop.watch.relax_reason
    assert reason is not None and reason.startswith("no valid reply from servo 5")
    peer.servo(5).silent_until = 0.0
    loop.read()
    assert loop.watch.relax_reason is None


def test_every_servo_quiet_while_the_host_was_late_is_not_blamed_on_cables() -> None:
    bus, _, peer = make_bus(small_rig(), fault_policy=POLICY)
    loop = Loop(bus, silence("stop"))
    for _ in range(20):  # the usual gap between reads: 20 ms
        loop.read()
        bus.clock.advance(0.02)  # type: ignore[attr-defined]
    bus.clock.advance(0.08)  # type: ignore[attr-defined]  # the host stalls
    for s in peer.servos:
        s.silent_until = math.inf
    with pytest.raises(DeviceTimeoutError) as err:
        loop.until(1.0, np.zeros(6))
    text = str(err.value)
    assert "no valid reply from any servo" in text
    assert re.search(r"the host was late by (79|80|81) ms", text)
    assert "not keeping up" in text and "cable" not in text


def test_every_servo_quiet_on_a_host_that_kept_time_points_at_the_bus_not_a_servo() -> None:
    bus, _, peer = make_bus(small_rig(), fault_policy=POLICY)
    loop = Loop(bus, silence("stop"))
    loop.read()
    for s in peer.servos:
        s.silent_until = math.inf
    with pytest.raises(DeviceTimeoutError) as err:
        loop.until(1.0, np.zeros(6))
    text = str(err.value)
    assert "every servo went quiet at once" in text
    assert "power supply, the USB adapter and the baud rate" in text


def test_every_servo_quiet_on_an_emulated_bus_points_at_the_emulator() -> None:
    """The factory says it opened an emulator (no guessing from the port's name)."""
    bus, _, peer = make_bus(small_rig(), fault_policy=POLICY, emulated=True)
    loop = Loop(bus, silence("stop"))
    loop.read()
    for s in peer.servos:
        s.silent_until = math.inf
    with pytest.raises(DeviceTimeoutError, match="the emulator is not keeping up"):
        loop.until(1.0, np.zeros(6))


@pytest.mark.parametrize("emulated, says", [
    (True, "the emulator is not keeping up"), (False, "check the bus's power supply")])
def test_one_read_part_quiet_as_a_whole_is_not_blamed_on_each_servos_cable(
        emulated: bool, says: str) -> None:
    """Reads alternate between the bus's two parts (servos 0, 2, 4 and 1, 3, 5); when
    every servo of one part goes quiet at once, the message says so instead of asking
    for three cables to be checked."""
    bus, _, peer = make_bus(small_rig(), fault_policy=POLICY, emulated=emulated)
    watch = SilenceWatch(bus, silence("continue"), bus.rig.loop.slew_deg_s)
    for k in range(4):
        watch.note_read(bus.clock.now())
        watch.update(bus.read_state(part=(k % 2, 2)), bus.clock.now())
        bus.clock.advance(0.02)  # type: ignore[attr-defined]
    for i in (0, 2, 4):
        peer.servos[i].silent_until = math.inf
    for k in range(30):
        bus.write_goals_deg(np.zeros(6))
        watch.note_read(bus.clock.now())
        watch.update(bus.read_state(part=(k % 2, 2)), bus.clock.now())
        bus.clock.advance(0.02)  # type: ignore[attr-defined]
    text = " | ".join(watch.drain_events())
    assert "every servo one read asks" in text and says in text, text
    assert "check its cable" not in text, text
    # a single servo of a part going quiet is still its own cable's business
    bus, _, peer = make_bus(small_rig(), fault_policy=POLICY, emulated=emulated)
    watch = SilenceWatch(bus, silence("continue"), bus.rig.loop.slew_deg_s)
    peer.servos[2].silent_until = math.inf
    for k in range(30):
        bus.write_goals_deg(np.zeros(6))
        watch.note_read(bus.clock.now())
        watch.update(bus.read_state(part=(k % 2, 2)), bus.clock.now())
        bus.clock.advance(0.02)  # type: ignore[attr-defined]
    text = " | ".join(watch.drain_events())
    assert "check its cable" in text and "every servo one read asks" not in text, text


def test_a_rebooted_servo_comes_back_where_it_is_and_eases_to_its_goals() -> None:
    from firmware_protocol import dynamixel as dx

    rig = small_rig()
    bus, _, peer = make_bus(rig, fault_policy=POLICY)
    loop = Loop(bus, silence("continue"))
    cal = rig.servos[4]
    goals = np.full(6, 0.5 * cal.max_deg)
    with bus.torque(handle_signals=False):
        assert bus.drain_events() == []  # the loop drains them: from now on events
        loop.write(goals)
        servo = peer.servo(5)
        servo.inject_hardware_error(dx.HardwareError.OVERLOAD)  # torque off in it
        servo.set_motion(float(deg_to_ticks(cal, cal.min_deg)), 0.0, 0.0)  # sagged to its stop
        bus.clock.advance(0.01)  # type: ignore[attr-defined]
        loop.read()  # the Alert: read its error, reboot it
        assert bus.stats.reboots[4] == 1 and servo.torque_enabled
        # torque came back where it is, not at the goal it had
        assert servo.goal == deg_to_ticks(cal, cal.min_deg)
        events = bus.drain_events()
        assert any("hardware error 0x20" in e and "rebooting it" in e for e in events)
        assert any(e.startswith("servo 5 (riThumbIPz) rebooted: torque on where it is")
                   for e in events)
        step = rig.loop.slew_deg_s / RATE_HZ
        loop.write(goals)  # eases back at the slew limit
        assert bus.last_goals_deg[4] == pytest.approx(cal.min_deg + step)
        lo, hi = (np.array([getattr(s, k) for s in rig.servos]) for k in ("min_deg", "max_deg"))
        follow = np.clip(goals, lo, hi)
        assert (np.delete(bus.last_goals_deg, 4) == np.delete(follow, 4)).all()  # the others
        for _ in range(int((goals[0] - cal.min_deg) / step) + 2):
            loop.write(goals)
        assert bus.last_goals_deg[4] == pytest.approx(goals[0])
        assert not loop.watch.steering
