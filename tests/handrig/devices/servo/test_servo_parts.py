"""The driver's parts through their public interfaces, with a fake transport: no pty, no thread.

The fake (tests/handrig/devices/servo/servo_fakes.py) subclasses the driver's Transport ABC and
feeds every write to the byte-level emulator in-process; replies arrive at wire
time on a FakeClock. What the servos got is read from the emulated servos.
"""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from firmware_protocol import dynamixel as dx
from handrig.config.rig import RigConfig
from handrig.devices.servo import FaultPolicy
from handrig.devices.servo.positions import deg_to_ticks, ticks_to_deg
from handrig.devices.servo.transport import Transport
from handrig.devices.servo.wire import WireBudget, cycle_bytes, read_bytes, wire_time_s
from handrig.errors import SafetyStop, ServoFault
from sim.dxl_bus import FaultSpec
from tests.handrig.devices.servo.servo_fakes import PeerBus
from tests.helpers.servos import BAUD, make_bus, small_rig


def ticks(rig: RigConfig, goals: np.ndarray) -> list[int]:
    return [deg_to_ticks(s, float(g)) for s, g in zip(rig.servos, goals, strict=True)]


def sync_write_golden(rig: RigConfig, goal_ticks: list[int]) -> bytes:
    """The goal Sync Write as the emulator's codec builds it (never stuffed: see goals.py)."""
    items = [(s.id, t.to_bytes(4, "little", signed=True))
             for s, t in zip(rig.servos, goal_ticks, strict=True)]
    params = dx.sync_write_params(dx.Reg.GOAL_POSITION, 4, items)
    return dx.build_instruction(dx.BROADCAST_ID, dx.Instruction.SYNC_WRITE, params)


def test_the_fake_is_a_transport() -> None:
    bus, transport, _ = make_bus(connect=False)
    assert isinstance(transport, Transport)
    assert bus.transport is transport


def test_commissioning_through_the_fake() -> None:
    bus, _, peer = make_bus()
    text = "\n".join(bus.commissioning)
    assert "no USB latency timer on fake:emulator: skipped" in text
    assert "RETURN_DELAY_TIME 250 -> 0" in text
    assert "present state by Fast Sync Read" in text
    assert all(peer.servo(s.id).get(dx.Reg.RETURN_DELAY_TIME) == 0 for s in small_rig().servos)
    assert bus.models == {s.id: 1200 for s in small_rig().servos}


def test_goal_write_is_one_port_write_of_the_golden_sync_write() -> None:
    rig = small_rig()
    bus, transport, peer = make_bus(rig)
    goals = np.array([0.5 * (s.min_deg + s.max_deg) for s in rig.servos])
    before = len(transport.writes)
    assert bus.write_goals_deg(goals) == 0
    assert len(transport.writes) == before + 1
    assert transport.writes[-1] == sync_write_golden(rig, ticks(rig, goals))
    assert [peer.servo(s.id).goal for s in rig.servos] == ticks(rig, goals)
    np.testing.assert_array_equal(bus.last_goals_deg, goals)


def test_write_and_read_is_one_port_write_then_the_short_way() -> None:
    rig = small_rig()
    bus, transport, peer = make_bus(rig, temperature_every=0)
    goals = np.array([s.max_deg + 50.0 for s in rig.servos])  # all beyond the limits
    before = len(transport.writes)
    clamped, state = bus.write_and_read(goals)
    assert clamped == 6 and state.all_fresh and bus.last_read_whole
    assert len(transport.writes) == before + 1
    limits = np.array([s.max_deg for s in rig.servos])
    golden = sync_write_golden(rig, ticks(rig, limits))
    assert transport.writes[-1].startswith(golden)
    request = dx.parse_instruction(transport.writes[-1][len(golden):])
    assert request.instruction == dx.Instruction.FAST_SYNC_READ
    assert [peer.servo(s.id).goal for s in rig.servos] == ticks(rig, limits)


def test_whole_read_decodes_the_emulated_servos() -> None:
    rig = small_rig()
    bus, _, peer = make_bus(rig, temperature_every=0)
    for j, s in enumerate(rig.servos):
        peer.servo(s.id).set_motion(s.zero_ticks + 37.0 * j - 50.0, 3.0 * j - 7.0, 20.0 * j)
    state = bus.read_state()
    assert bus.last_read_whole and state.all_fresh and (state.age_s == 0).all()
    want = [ticks_to_deg(s, peer.servo(s.id).present) for s in rig.servos]
    np.testing.assert_allclose(state.positions_deg, want, atol=1e-9)
    assert np.isfinite(state.velocities_dps).all() and np.isfinite(state.currents_ma).all()
    assert state.timestamp_s == bus.clock.now()


def test_a_late_reply_is_recognised_and_dropped() -> None:
    rig = small_rig()
    bus, transport, peer = make_bus(rig, temperature_every=0, reply_timeout_s=0.01,
                                    fault_policy=FaultPolicy(read_retries=0))
    transport.extra_delay_s = 0.006  # the next reply comes after its read gave up
    assert bus.read_state(bus.clock.now() + 0.004).stale.all()
    for j, s in enumerate(rig.servos):  # new positions: the late reply holds the old ones
        peer.servo(s.id).set_motion(s.zero_ticks + 11.0 * j + 3.0, 0.0, 0.0)
    state = bus.read_state(bus.clock.now() + 0.02)
    assert bus.stats.late_replies == 1 and state.stats.late_replies == 1
    assert state.all_fresh
    want = [ticks_to_deg(s, peer.servo(s.id).present) for s in rig.servos]
    np.testing.assert_allclose(state.positions_deg, want, atol=1e-9)


def test_a_read_that_cannot_fit_its_deadline_is_not_sent() -> None:
    bus, transport, _ = make_bus()
    before, reads = len(transport.writes), bus.stats.reads
    state = bus.read_state(bus.clock.now() + 0.5 * bus.read_wire_s(6))
    assert state.stale.all() and bus.stats.skipped_reads == 1 and bus.stats.reads == reads
    assert len(transport.writes) == before


def test_after_a_failed_reply_the_line_must_be_quiet_first() -> None:
    bus, transport, _ = make_bus(temperature_every=0)
    transport.peer.faults = FaultSpec(drop=1.0)
    assert bus.read_state(bus.clock.now() + 0.01).stale.all()
    transport.peer.faults = FaultSpec()
    wire_s = bus.read_wire_s(6)
    tight = bus.read_state(bus.clock.now() + wire_s + 0.5 * bus.reply_gap_s)
    assert tight.stale.all() and bus.stats.skipped_reads == 1
    bus.clock.sleep(bus.reply_gap_s)
    assert bus.read_state(bus.clock.now() + wire_s + 0.5 * bus.reply_gap_s).all_fresh



def test_the_quiet_wait_a_loop_counts_runs_from_the_late_bytes_that_came() -> None:
    bus, transport, _ = make_bus(temperature_every=0, reply_timeout_s=0.01,
                                 fault_policy=FaultPolicy(read_retries=0))
    assert bus.quiet_wait_s() == 0.0  # no reply failed
    transport.extra_delay_s = 0.006  # the reply comes after its read gave up
    assert bus.read_state(bus.clock.now() + 0.004).stale.all()
    assert bus.quiet_wait_s() == pytest.approx(bus.reply_gap_s, abs=1e-4)
    bus.clock.sleep(0.004)  # the late reply has come in meanwhile, unread
    # counted from those bytes, taken in now: the quiet starts again
    assert bus.quiet_wait_s() == pytest.approx(bus.reply_gap_s, abs=1e-4)
    bus.clock.sleep(bus.reply_gap_s)
    assert bus.quiet_wait_s() == 0.0



def test_a_part_read_asks_its_servos_by_a_request_built_once() -> None:
    from handrig.devices.servo import codec as hcodec
    from handrig.devices.servo.fast_read import ORDERS_KEPT

    rig = small_rig()
    bus, transport, peer = make_bus(rig, temperature_every=0)
    ids = [s.id for s in rig.servos]
    requests = []
    for k in range(4):
        assert not bus.read_state(part=(k % 2, 2)).stale.any()
        requests.append(transport.writes[-1])
    plan = bus.reader.plan
    want = [hcodec.read_request(hcodec.INST_FAST_SYNC_READ, plan.address, plan.data_len,
                                bytes(ids[i::2])) for i in (0, 1)]
    assert requests == want * 2
    fast = bus.reader.fast
    assert requests[0] is requests[2] and len(fast._orders_of) == 2  # built once each
    peer.servo(ids[2]).silent_until = np.inf  # part 0's retry asks the servos it lost
    state = bus.read_state(bus.clock.now() + 0.05, part=(0, 2))  # room for a retry
    assert state.stale[2] and not state.stale[[0, 1, 3, 4, 5]].any()
    assert bus.stats.retries >= 1 and 2 < len(fast._orders_of) <= ORDERS_KEPT
    retry = [o for o in fast._orders_of.values() if o.ids.tobytes() not in
             (bytes(ids[0::2]), bytes(ids[1::2]))]
    assert retry and all(set(o.ids.tolist()) <= {ids[2], ids[4]} for o in retry)


def test_fallback_to_sync_read_at_connect() -> None:
    rig = small_rig()
    peer = PeerBus(rig)
    peer.ignore_fast_sync_read = True
    bus, _, _ = make_bus(rig, peer=peer)
    assert not bus.use_fast_sync_read and bus.stats.fallbacks == 1
    assert bus.read_state().all_fresh


def test_hardware_error_reboots_per_policy() -> None:
    bus, _, peer = make_bus()
    with bus.torque(handle_signals=False):
        peer.servo(5).inject_hardware_error(dx.HardwareError.OVERLOAD)
        state = bus.read_state(bus.clock.now() + 0.5)
        assert state.hardware_errors[4] == 0x20
        assert bus.stats.reboots[4] == 1 and peer.servo(5).counters["reboots"] == 1
        assert peer.servo(5).torque_enabled  # given back after the reboot
    assert not any(peer.servo(s.id).torque_enabled for s in small_rig().servos)


def test_hardware_error_stops_under_the_stop_policy() -> None:
    bus, _, peer = make_bus(fault_policy=FaultPolicy(on_hardware_error="stop"))
    with pytest.raises(ServoFault) as info, bus.torque(handle_signals=False):
        peer.servo(2).inject_hardware_error(dx.HardwareError.OVERLOAD)
        bus.read_state()
    assert info.value.servo_id == 2 and info.value.bits == 0x20
    assert not any(peer.servo(s.id).torque_enabled for s in small_rig().servos)


def test_a_silence_rearms_the_watchdog_before_the_goals() -> None:
    rig = small_rig()
    bus, _, peer = make_bus(rig, temperature_every=0)
    with bus.torque(handle_signals=False):
        bus.clock.sleep(0.3)  # longer than the 100 ms Bus Watchdog
        bus.write_goals_deg(np.zeros(6))
        assert bus.stats.watchdog_gaps == 1
        assert all(peer.servo(s.id).get(dx.Reg.BUS_WATCHDOG) == 5 for s in rig.servos)


@pytest.mark.parametrize("sig", [signal.SIGHUP, signal.SIGQUIT, signal.SIGTERM])
def test_torque_context_takes_sighup_and_sigquit_like_sigterm(sig: signal.Signals) -> None:
    rig = small_rig()
    bus, _, peer = make_bus(rig)
    seen: list[str] = []
    before = signal.getsignal(sig)
    with bus.torque(on_signal=seen.append):
        os.kill(os.getpid(), sig)
        bus.write_goals_deg(np.zeros(6))  # the handler runs in the main thread
        assert seen == [sig.name] and bus.torque_enabled
    assert not any(peer.servo(s.id).torque_enabled for s in rig.servos)
    assert signal.getsignal(sig) is before
    with pytest.raises(SafetyStop, match=sig.name), bus.torque():
        os.kill(os.getpid(), sig)
        bus.write_goals_deg(np.zeros(6))
    assert not any(peer.servo(s.id).torque_enabled for s in rig.servos)
    assert signal.getsignal(sig) is before


# ---------------------------------------------------------------------- the wire budget
def test_wire_budget_line_free_and_fits() -> None:
    b = WireBudget(BAUD, reply_gap_s=0.0015, reply_timeout_s=0.004)
    b.sent(100, now=1.0)
    assert b.free_at == pytest.approx(1.001) and b.last_tx_s == 1.0
    b.sent(50, now=1.0005)  # queued behind the first
    assert b.free_at == pytest.approx(1.0015)
    assert b.request_start(1.0, held_bytes=10, last_rx_s=-np.inf) == pytest.approx(1.0016)
    assert b.fits(1.0, 100, 1.001) and not b.fits(1.0, 101, 1.001)
    assert b.reply_deadline(1.0) == pytest.approx(1.0055)
    b.reply_in(1.0008)
    assert b.free_at == pytest.approx(1.0008)


def test_wire_budget_quiet_rule_counts_from_the_failure_or_the_last_byte() -> None:
    b = WireBudget(BAUD, reply_gap_s=0.002, reply_timeout_s=0.004)
    assert b.take_quiet_wait(5.0, None) is None
    b.failed(5.0)
    assert b.request_start(5.0, 0, last_rx_s=4.0) == pytest.approx(5.002)
    assert b.request_start(5.0, 0, last_rx_s=5.001) == pytest.approx(5.003)
    assert b.take_quiet_wait(5.0005, deadline_s=5.002) == (5.0, pytest.approx(0.0015))
    assert b.take_quiet_wait(5.0005, None) is None  # taken once
    assert b.request_start(5.0005, 0, last_rx_s=5.001) == 5.0005
    assert b.quiet_wait_s(5.0005, last_rx_s=5.001) == 0.0  # the quiet was taken


def test_wire_budget_quiet_wait_is_what_the_quiet_adds_to_the_wire() -> None:
    b = WireBudget(BAUD, reply_gap_s=0.002, reply_timeout_s=0.004)
    assert b.quiet_wait_s(5.0, last_rx_s=4.0) == 0.0
    b.sent(500, now=5.0)  # on the wire until 5.005
    b.failed(5.0)
    assert b.quiet_wait_s(5.0, last_rx_s=4.0) == 0.0  # quiet by 5.002, the wire busy longer
    assert b.quiet_wait_s(5.0, last_rx_s=5.004) == pytest.approx(0.001)
    b.reply_in(5.0)
    assert b.quiet_wait_s(5.0005, last_rx_s=4.0) == pytest.approx(0.0015)


def test_cycle_and_read_bytes() -> None:
    assert cycle_bytes(20) == 14 + 100 + 14 + 20 + 8 + 160
    assert read_bytes(20, 4, True) == 14 + 20 + 8 + 160
    assert read_bytes(20, 4, False) == 14 + 20 + 15 * 20
    assert wire_time_s(100, BAUD) == pytest.approx(0.001)
