"""DynamixelBus against the byte-level emulator through the real SDK port: its reads
(Fast Sync Read and its fall-back, temperatures, late replies, reads of parts), the
watchdog, housekeeping and what the wire can carry by a deadline.

Every assertion about what the servos got is read from the emulated servos' own
registers, not from the driver.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from firmware_protocol.dynamixel import Reg as SimReg
from handrig.devices.servo import DynamixelBus, FaultPolicy
from handrig.devices.servo.positions import deg_to_ticks, ticks_to_deg
from handrig.errors import DeviceTimeoutError
from sim.dxl_bus import FaultSpec, SimBus
from tests.helpers.servos import RIG, goals_received, small_rig, tick_limits


@pytest.mark.parametrize("fast", [True, False], ids=["fast", "sync"])
def test_temperatures_read_every_so_often(sim: SimBus, fast: bool) -> None:
    b = DynamixelBus(sim.port_path, small_rig(), baud=1_000_000, temperature_every=3)
    b.connect()
    try:
        b.use_fast_sync_read = fast
        state = b.read_state(b.clock.now() + 0.05)
        assert np.all(np.isfinite(state.temperatures_c))
        assert np.all((state.temperatures_c > 0) & (state.temperatures_c < 100))
        inst = 0x8A if fast else 0x82
        before, retries = sim.stats.by_instruction[inst], b.stats.retries
        for _ in range(3):
            b.read_state(b.clock.now() + 0.05)
        # three state reads and one temperature read (every third state read), and the
        # retries of a read a loaded machine's emulator answered too late (each one more)
        assert sim.stats.by_instruction[inst] - before == 4 + b.stats.retries - retries
    finally:
        b.close()


def test_falls_back_to_sync_read_without_fast_sync_read() -> None:
    rig = small_rig()
    with SimBus.from_rig(rig) as sim:
        # servos whose firmware ignores Fast Sync Read (a broadcast gets no error status);
        # the emulator has no switch for it, so its fast-read handler is replaced
        sim._fast_read = lambda requests, now: []  # type: ignore[method-assign]
        b = DynamixelBus(sim.port_path, rig, baud=1_000_000)
        b.connect()
        try:
            assert not b.use_fast_sync_read
            assert b.stats.fallbacks == 1
            assert any("falling back from Fast Sync Read to Sync Read" in line
                       for line in b.commissioning)
            assert b.read_state().all_fresh
        finally:
            b.close()


def test_falls_back_at_runtime_after_failed_fast_reads(sim: SimBus, bus: DynamixelBus) -> None:
    assert bus.use_fast_sync_read
    sim._fast_read = lambda requests, now: []  # type: ignore[method-assign]
    states = [bus.read_state(bus.clock.now() + 0.02) for _ in range(12)]
    assert not bus.use_fast_sync_read and bus.stats.fallbacks == 1
    assert states[-1].all_fresh


def test_write_and_read_sends_goals_with_the_read(sim: SimBus, bus: DynamixelBus) -> None:
    rig = small_rig()
    goals = np.array([s.max_deg + 50.0 for s in rig.servos])  # all beyond the limits
    clamped, state = bus.write_and_read(goals)
    assert clamped == 6 and state.all_fresh
    _, hi = tick_limits(rig)
    for _ in range(100):
        if goals_received(sim, rig).tolist() == hi.tolist():
            break
        time.sleep(0.01)
    assert goals_received(sim, rig).tolist() == hi.tolist()
    assert bus.stats.writes == 1
    np.testing.assert_array_equal(bus.last_goals_deg, [s.max_deg for s in rig.servos])


@pytest.mark.parametrize("level", [0, 1])
def test_status_return_level_raised_to_two(level: int) -> None:
    rig = small_rig(2)
    with SimBus.from_rig(rig) as sim:
        sim.servo(2).set(SimReg.STATUS_RETURN_LEVEL, level)
        b = DynamixelBus(sim.port_path, rig, baud=1_000_000)
        b.connect()
        try:
            assert sim.servo(2).status_return_level == 2
            assert any(f"STATUS_RETURN_LEVEL {level}" in line and "-> 2" in line
                       for line in b.commissioning)
            with b.torque():
                assert sim.servo(2).torque_enabled
        finally:
            b.close()


def test_fresh_readings_are_true_under_faults() -> None:
    """Whatever the faults, a reading marked fresh is the servo's actual position."""
    rig = RIG
    spec = FaultSpec(drop=0.1, corrupt=0.1, wrong_id=0.1, truncate=0.2, seed=11)
    with SimBus.from_rig(rig) as sim:
        b = DynamixelBus(sim.port_path, rig, baud=1_000_000)
        b.connect()
        try:
            # distinct positions per servo, so a reading given to the wrong servo shows
            with sim.lock:
                for k, s in enumerate(rig.servos):
                    sim.servo(s.id).set_motion(s.zero_ticks + 7.0 * (k + 1), 0.0, 0.0)
            sim.faults = spec
            fresh = 0
            for _ in range(200):
                state = b.read_state(b.clock.now() + 0.02)
                true = np.array([ticks_to_deg(s, sim.servo(s.id).present) for s in rig.servos])
                ok = ~state.stale
                np.testing.assert_allclose(state.positions_deg[ok], true[ok], atol=1e-9)
                fresh += int(ok.sum())
            sim.faults = FaultSpec()
            assert fresh > 1000 and b.stats.retries > 10
        finally:
            b.close()


def test_tripped_watchdog_found_and_rearmed(sim: SimBus) -> None:
    rig = small_rig()
    b = DynamixelBus(sim.port_path, rig, baud=1_000_000, temperature_every=1)
    b.connect()
    try:
        with b.torque():
            time.sleep(0.3)  # the host "hangs": every servo's watchdog (100 ms) trips
            assert all(sim.servo(s.id).get(SimReg.BUS_WATCHDOG) in (-1, 0xFF) for s in rig.servos)
            b.read_state(b.clock.now() + 0.05)
            assert b.stats.watchdog_trips == 6
            assert all(sim.servo(s.id).get(SimReg.BUS_WATCHDOG) == 5 for s in rig.servos)
            goals = np.array([0.5 * s.max_deg for s in rig.servos])
            b.write_goals_deg(goals)
            want = [deg_to_ticks(s, float(g)) for s, g in zip(rig.servos, goals, strict=True)]
            for _ in range(100):
                if goals_received(sim, rig).tolist() == want:
                    break
                time.sleep(0.01)
            assert goals_received(sim, rig).tolist() == want  # goals accepted again
    finally:
        b.close()


def test_goals_after_a_silence_rearm_the_watchdog_first(sim: SimBus) -> None:
    """A host pause longer than the Bus Watchdog (a long garbage collection, say) trips
    it and the servos refuse goals; the next goal write re-arms it before the goals."""
    rig = small_rig()
    b = DynamixelBus(sim.port_path, rig, baud=1_000_000, temperature_every=0)
    b.connect()
    try:
        with b.torque():
            time.sleep(0.3)  # silent: every servo's watchdog (100 ms) trips
            assert all(sim.servo(s.id).get(SimReg.BUS_WATCHDOG) in (-1, 0xFF) for s in rig.servos)
            goals = np.array([0.5 * s.max_deg for s in rig.servos])
            b.write_goals_deg(goals)  # no read in between: the write alone must recover
            assert b.stats.watchdog_gaps == 1
            # at once (not after waiting for the emulator, which a loaded machine can
            # starve for longer than the watchdog): no silence this time, nothing re-armed
            b.write_goals_deg(goals)
            assert b.stats.watchdog_gaps == 1
            want = [deg_to_ticks(s, float(g)) for s, g in zip(rig.servos, goals, strict=True)]
            for _ in range(100):
                if goals_received(sim, rig).tolist() == want:
                    break
                time.sleep(0.01)
            assert goals_received(sim, rig).tolist() == want
            assert all(sim.servo(s.id).get(SimReg.BUS_WATCHDOG) == 5 for s in rig.servos)
    finally:
        b.close()


def test_late_replies_are_never_taken_for_a_later_read() -> None:
    """A reply delayed past its read's deadline arrives during the next read: dropped."""
    rig = small_rig()
    with SimBus.from_rig(rig) as sim:
        # no retries: one request per read, so the emulator (which answers in turn,
        # sleeping through each delayed reply) never builds a queue
        b = DynamixelBus(sim.port_path, rig, baud=1_000_000,
                         fault_policy=FaultPolicy(read_retries=0))
        b.connect()
        try:
            sim.faults = FaultSpec(delay=0.15, delay_s=0.006, seed=4)
            fresh = 0
            for k in range(120):
                # new, distinct positions before every read: an old reply would show
                with sim.lock:  # the emulator thread moves its servos under this lock
                    for j, s in enumerate(rig.servos):
                        sim.servo(s.id).set_motion(s.zero_ticks + 5.0 * j + (k % 40), 0.0, 0.0)
                state = b.read_state(b.clock.now() + 0.004)
                true = np.array([ticks_to_deg(s, sim.servo(s.id).present) for s in rig.servos])
                ok = ~state.stale
                np.testing.assert_allclose(state.positions_deg[ok], true[ok], atol=1e-9)
                fresh += int(ok.any())
                time.sleep(0.001)  # the next read starts before the late reply arrives
            sim.faults = FaultSpec()
            assert b.stats.late_replies > 0 and fresh > 60
        finally:
            b.close()


def test_one_late_reply_does_not_make_every_later_read_late() -> None:
    """With wire timing, a late reply still on the wire delays the next one (the bus is
    half duplex); the driver waits for the line to go quiet instead of piling up."""
    rig = RIG  # 20 servos at 1 Mbps: a cycle takes 3.2 ms of wire, the read budget 4 ms
    with SimBus.from_rig(rig, wire_timing=True) as sim:
        # no fallback to Sync Read: a loaded machine's stall can fail ten reads in a row
        # (a 2026-12-06 CI run), and Sync Read's 20 replies do not fit this budget; the
        # test is about the quiet line after a late reply, not about the fallback
        b = DynamixelBus(sim.port_path, rig, baud=1_000_000, read_fields="position",
                         fault_policy=FaultPolicy(fast_failures_before_fallback=10_000))
        b.connect()
        try:
            sim.faults = FaultSpec(delay=0.02, delay_s=0.004, seed=8)
            failed = 0
            for _ in range(250):
                b.write_goals_deg(np.zeros(20))
                failed += int(b.read_state().stale.any())
            sim.faults = FaultSpec()
            assert sim.fault_counts["delayed"] >= 2
            # piling up makes nearly every read after the first late reply late (~245 of
            # 250); the injected delays alone cost about 10. A starved in-process emulator
            # costs more: 79 in a clean-clone CI run beside a busy core (2026-12-06 05:00)
            assert failed < 125, (failed, b.stats.summary())
        finally:
            b.close()


def test_whole_reads_return_their_own_snapshot(sim: SimBus, bus: DynamixelBus) -> None:
    """The usual read (every servo's reply intact, no alert) takes a shorter way through
    the driver; what it returns is the same: fresh readings of the emulated servos, the
    counters as they are at return, arrays that belong to that state alone."""
    rig = small_rig()
    first = bus.read_state()  # the first read also fetches the temperatures
    states = [bus.read_state() for _ in range(3)]
    assert bus.last_read_whole  # the last one went the short way
    for k, s in enumerate(states):
        assert not s.stale.any() and (s.age_s == 0).all()
        assert (s.hardware_errors == 0).all() and (s.status_errors == 0).all()
        assert s.stats.reads == first.stats.reads + k + 1
        assert np.isfinite(s.temperatures_c).all()
        np.testing.assert_array_equal(s.temperatures_c, first.temperatures_c)
    assert states[-1].stats.summary() == bus.stats.summary()
    assert states[-1].stats is not bus.stats
    # a caller scribbling on one state changes neither the driver nor the next state
    states[0].positions_deg[:] = 999.0
    states[0].stale[:] = True
    states[0].stats.reads = -1
    nxt = bus.read_state()
    true = np.array([ticks_to_deg(s, sim.servo(s.id).present) for s in rig.servos])
    np.testing.assert_allclose(nxt.positions_deg, true, atol=1e-9)
    assert not nxt.stale.any() and bus.stats.reads == nxt.stats.reads > 0
    for a, b in zip(vars(states[-1]).values(), vars(nxt).values(), strict=True):
        if isinstance(a, np.ndarray):
            assert not np.shares_memory(a, b)
    assert nxt.timestamp_s > states[-1].timestamp_s


@pytest.mark.parametrize("read", [True, False])
def test_servos_move_while_the_bus_is_busy_with_wire_timing(read: bool) -> None:
    """The emulator's housekeeping (kinematic motion, watchdogs) runs in the replies'
    wire time, or once overdue when no reply leaves such time (goal writes only)."""
    rig = RIG  # 20 servos: at 4 Mbps a Fast Sync Read reply takes 420 us of wire
    goals = np.array([0.5 * s.max_deg for s in rig.servos])
    # the servos at 4 Mbps too: a servo answers only at its own Baud Rate
    with SimBus.from_rig(rig, wire_timing=True,
                         bauds={s.id: 4_000_000 for s in rig.servos}) as sim:
        advances: list[float] = []  # when the emulated servos' motion was advanced
        housekeeping = sim._housekeeping

        def spy(now: float) -> None:
            before = sim._last_advance
            housekeeping(now)
            if sim._last_advance != before:
                advances.append(sim._last_advance)

        sim._housekeeping = spy  # type: ignore[method-assign]
        b = DynamixelBus(sim.port_path, rig, baud=4_000_000, read_fields="position")
        b.connect()
        try:
            with b.torque():
                t_end = time.monotonic() + 3.0
                k = 0
                while time.monotonic() < t_end:  # back to back: the bus never idles
                    b.write_goals_deg(goals)
                    if read:
                        b.read_state()
                    else:
                        time.sleep(0.0002)
                    k += 1
                    if k % 50 == 0:
                        with sim.lock:
                            true = np.array([ticks_to_deg(s, sim.servo(s.id).present)
                                             for s in rig.servos])
                        if np.allclose(true, goals, atol=0.2):
                            break
                np.testing.assert_allclose(true, goals, atol=0.2)
                assert b.stats.watchdog_gaps == 0
                # every 2 ms in the replies' wire time; once overdue (10 ms) without replies.
                # The bound with reads only has to tell the first from the second: a full
                # fresh-clone run on a host losing CPU to other guests gave a 4.4 ms median
                step = float(np.median(np.diff(advances[-50:])))
                assert step < (0.006 if read else 0.015), step
        finally:
            b.close()


def test_a_read_the_wire_cannot_carry_by_its_deadline_is_not_sent(sim: SimBus) -> None:
    """On a half-duplex bus a reply still arriving when the next goals go out collides
    with them: a read that cannot fit before its deadline is skipped, its servos stale;
    reads that never fit stop the bus with the reason."""
    rig = small_rig()
    for servo in sim.servos:  # a servo answers only at its own Baud Rate
        servo.set(SimReg.BAUD_RATE, 1)  # 57600
    b = DynamixelBus(sim.port_path, rig, baud=57_600,
                     fault_policy=FaultPolicy(max_stale_reads=3))
    b.connect()
    fsr = 0x8A
    try:
        fresh = b.read_state()
        wire_s = b.read_wire_s(len(rig.servos))  # about 19 ms at 57600 baud
        reads = sim.stats.by_instruction[fsr]
        state = b.read_state(b.clock.now() + 0.5 * wire_s)
        assert state.stale.all() and (state.age_s > 0).all()
        np.testing.assert_array_equal(state.positions_deg, fresh.positions_deg)
        # the goals write_and_read sends first count: the read no longer fits after them
        goal_wire_s = (14 + 5 * len(rig.servos)) * 10 / 57_600
        _, state = b.write_and_read(np.zeros(len(rig.servos)),
                                    b.clock.now() + wire_s + 0.5 * goal_wire_s)
        assert state.stale.all()
        assert sim.stats.by_instruction[fsr] == reads  # no read was sent
        # fewer than max_stale_reads in a row: not a fault
        assert b.stats.skipped_reads == 2 and b.stats.timeouts == 0
        b.clock.sleep(2 * goal_wire_s)  # the goals are off the wire
        assert not b.read_state(b.clock.now() + 2 * wire_s + 0.01).stale.any()
        for _ in range(2):
            assert b.read_state(b.clock.now() + 0.5 * wire_s).stale.all()
        with pytest.raises(DeviceTimeoutError, match="fitted its deadline 3 times in a row"):
            b.read_state(b.clock.now() + 0.5 * wire_s)
    finally:
        b.close()


def test_a_reply_behind_writes_still_on_the_wire_is_waited_for() -> None:
    """Torque-on arms the Bus Watchdogs by two broadcast Sync Writes, then reads them
    back: with wire timing the reply starts only once those writes are off the wire,
    later than the reply gap after the request. It must not count as a timeout.

    Counting the writes wrong times every such read out; a host that stalls the
    emulator's thread for tens of milliseconds (this machine does) times out one now
    and then: of three rounds of three, one must be clean."""
    with SimBus.from_rig(RIG, wire_timing=True) as sim:
        b = DynamixelBus(sim.port_path, RIG, baud=1_000_000, read_fields="position")
        b.connect()
        try:
            rounds = []
            for _ in range(3):
                before = b.stats.timeouts
                stale = 0
                for _ in range(3):
                    with b.torque():
                        b.write_goals_deg(np.zeros(len(RIG.servos)))
                        stale += int(b.read_state().stale.any())
                rounds.append((stale, b.stats.timeouts - before))
                if rounds[-1] == (0, 0):
                    break
            assert rounds[-1] == (0, 0), (rounds, b.stats.summary())
        finally:
            b.close()


def test_after_a_failed_read_the_wait_for_a_quiet_line_counts_against_the_deadline(
    sim: SimBus, bus: DynamixelBus
) -> None:
    """A reply that failed may still be on the wire: the next request waits for a quiet
    line first, so a read that fits only without that wait is not sent."""
    n = len(small_rig().servos)
    wire_s = bus.read_wire_s(n)
    # On a loaded machine this thread may lose the CPU between the failed read and the
    # next one for longer than the quiet wait, which is then over: the tight read fits
    # and is rightly sent. The scenario is tried until one tight read came before the
    # line was quiet; with the wait not counted, every one would be sent.
    for _ in range(10):
        sim.faults = FaultSpec(drop=1.0)
        assert bus.read_state(bus.clock.now() + 0.01).stale.all()  # every reply lost
        sim.faults = FaultSpec()
        sent, skipped = bus.stats.reads, bus.stats.skipped_reads
        tight = bus.read_state(bus.clock.now() + wire_s + 0.5 * bus.reply_gap_s)
        if bus.stats.reads == sent:
            break
    assert tight.stale.all() and bus.stats.reads == sent
    assert bus.stats.skipped_reads == skipped + 1
    # once the line has been quiet that long, the same tight deadline is enough again
    # (counted from the failure, not from each request: no read is kept out for good);
    # the read is sent, and answered unless a loaded machine made the replies late
    time.sleep(bus.reply_gap_s)
    sent, skipped, timeouts = bus.stats.reads, bus.stats.skipped_reads, bus.stats.timeouts
    again = bus.read_state(bus.clock.now() + wire_s + 0.5 * bus.reply_gap_s)
    assert again.sent and bus.stats.reads == sent + 1 and bus.stats.skipped_reads == skipped
    assert not again.stale.any() or bus.stats.timeouts > timeouts  # stale: its replies late



def test_housekeeping_between_reads_when_due_and_when_the_wire_has_room(sim: SimBus) -> None:
    b = DynamixelBus(sim.port_path, small_rig(), baud=1_000_000, temperature_every=2)
    b.connect()  # its read did the housekeeping: due again 2 reads later
    try:
        b.read_state(b.clock.now() + 0.05)
        assert not b.housekeeping(b.clock.now() + 0.05)  # not due yet
        b.reader.stats.reads += 1  # a read without time for the housekeeping leaves it due
        assert not b.housekeeping(b.clock.now() + 0.0001)  # due, but no room on the wire
        before = sim.stats.by_instruction[0x8A]
        assert b.housekeeping(b.clock.now() + 0.05)
        assert sim.stats.by_instruction[0x8A] - before == 1  # one temperature read
        assert not b.housekeeping(b.clock.now() + 0.05)  # done: not due again
        assert np.isfinite(b.read_state(b.clock.now() + 0.05).temperatures_c).all()
    finally:
        b.close()


def test_housekeeping_waits_for_the_room_it_took_before_but_not_for_ever(sim: SimBus) -> None:
    from handrig.devices.servo.reader import HOUSEKEEPING_FORCE_S

    b = DynamixelBus(sim.port_path, small_rig(), baud=1_000_000, temperature_every=2)
    b.connect()  # its read did the housekeeping, and timed it
    try:
        r = b.reader
        assert r._housekeeping_s > 0.0
        r.stats.reads += 2  # due again
        r._housekeeping_s = 0.2  # as if it had taken 200 ms on this bus
        assert not b.housekeeping(b.clock.now() + 0.05)  # the wire has room; the past not
        assert r._housekeeping_due() and r._housekeeping_due_at is not None
        r._housekeeping_due_at -= HOUSEKEEPING_FORCE_S  # put off for a second: it runs
        assert b.housekeeping(b.clock.now() + 0.05)
        assert not r._housekeeping_due() and r._housekeeping_s < 0.2
    finally:
        b.close()


def test_a_retry_starts_only_with_room_for_what_requests_have_taken_here(
        sim: SimBus, bus: DynamixelBus) -> None:
    reader = bus.reader
    assert not bus.read_state().stale.any()
    assert reader._attempt_extra_s >= 0.0  # learnt from the answered request
    reader._attempt_extra_s = 0.0  # answers as fast as the wire
    sim.servo(3).silent_until = math.inf  # one servo silent: every read fails on it
    time.sleep(0.01)
    before = bus.stats.retries
    bus.read_state(bus.clock.now() + 0.1)  # room for a retry
    assert bus.stats.retries > before
    time.sleep(0.01)
    reader._attempt_extra_s = 1.0  # as if answers took a second here
    before = bus.stats.retries
    state = bus.read_state(bus.clock.now() + 0.1)
    assert bus.stats.retries == before  # the wire has room; what it has taken does not
    assert state.stale.any()
    sim.servo(3).silent_until = 0.0


def test_a_read_of_one_part_asks_only_those_servos_and_marks_only_them(
        sim: SimBus, bus: DynamixelBus) -> None:
    first = bus.read_state()
    assert first.all_fresh and first.asked is None
    sim.servo(5).silent_until = math.inf  # rig index 4: in part 0 of 2 (indices 0, 2, 4)
    time.sleep(0.01)
    # a read the in-process emulator answered too late (its thread starved on a loaded
    # machine, as in a CI run beside a busy core) is read again, up to 5 times
    for _ in range(5):
        odd = bus.read_state(part=(1, 2))  # indices 1, 3, 5: servo 5 is not asked
        if not odd.stale.any():
            break
    assert odd.asked.tolist() == [False, True, False, True, False, True]
    assert not odd.stale.any()
    assert odd.age_s[[1, 3, 5]].max() < odd.age_s[[0, 2, 4]].min()  # the others are older
    for _ in range(5):
        before = bus.stats.stale_readings.copy()
        even = bus.read_state(part=(0, 2))
        if even.stale.tolist() == [False, False, False, False, True, False]:
            break
    assert even.asked.tolist() == [True, False, True, False, True, False]
    assert even.stale.tolist() == [False, False, False, False, True, False]
    assert even.positions_deg[4] == first.positions_deg[4]  # the last good value
    # that read counted a stale reading for servo 5 alone
    assert (bus.stats.stale_readings - before).tolist() == [0, 0, 0, 0, 1, 0]
    sim.servo(5).silent_until = 0.0
    # a part read is shorter on the wire than a whole one
    reader = bus.reader
    assert reader.read_wire_s(3) < reader.read_wire_s(6)
    with pytest.raises(ValueError, match="read parts"):
        bus.read_state(part=(0, 7))
