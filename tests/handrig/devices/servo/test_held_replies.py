"""A read timeout whose reply still comes in whole is the host's (``BusStats.host_timeouts``):
a servo answers within its Return Delay Time or not at all, so a whole, intact reply that
arrives after its deadline was held on its way (the host, an emulator, a USB adapter), not
lost on the bus. Nothing heard at all, or a reply cut short, stays the bus's.

The real driver on the in-process emulator through a fake transport on a FakeClock (the
process never wakes late and no CPU pressure is looked at): the compute-only lane.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np

from handrig.config.rig import RigConfig
from handrig.devices.servo import DynamixelBus, FaultPolicy, codec
from handrig.devices.servo.fast_read import NONE, Order
from handrig.devices.servo.link import HELD_MARGIN_S, HOST_STALL_S, LATE_LOOK_BYTES
from handrig.devices.servo.registers import Reg
from handrig.realtime import CpuPressure
from tests.handrig.devices.servo.servo_fakes import EmulatorTransport, PeerBus
from tests.helpers.servos import make_bus, small_rig

HELD_S = 0.006  # the reply comes this long after its wire time: after its read gave up


def _held_bus(rig: RigConfig | None = None) -> tuple[DynamixelBus, EmulatorTransport, PeerBus]:
    """The driver on ``rig`` (six servos), a 10 ms reply timeout and no retry."""
    return make_bus(rig or small_rig(), temperature_every=0, reply_timeout_s=0.01,
                    fault_policy=FaultPolicy(read_retries=0))


def test_a_reply_that_comes_whole_after_its_timeout_makes_it_the_hosts() -> None:
    bus, transport, _ = _held_bus()
    transport.extra_delay_s = HELD_S
    assert bus.read_state(bus.clock.now() + 0.004).stale.all()
    # at the deadline nothing says it was the host yet
    assert (bus.stats.timeouts, bus.stats.host_timeouts) == (1, 0)
    bus.clock.sleep(0.01)  # the held reply has come in, unread
    assert bus.read_state(bus.clock.now() + 0.02).all_fresh
    assert (bus.stats.timeouts, bus.stats.host_timeouts, bus.stats.late_replies) == (1, 1, 1)


def test_a_held_reply_found_behind_the_next_request_makes_it_the_hosts() -> None:
    bus, transport, _ = _held_bus()
    transport.extra_delay_s = HELD_S
    assert bus.read_state(bus.clock.now() + 0.004).stale.all()
    # the next read goes out before the held reply came: it is found ahead of its own reply
    state = bus.read_state(bus.clock.now() + 0.03)
    assert state.all_fresh
    assert (bus.stats.timeouts, bus.stats.host_timeouts, bus.stats.late_replies) == (1, 1, 1)


def test_silence_and_a_reply_that_never_comes_stay_the_buss() -> None:
    bus, transport, peer = _held_bus()
    for servo in peer.servos:
        servo.silent_until = math.inf  # nobody answers
    assert bus.read_state(bus.clock.now() + 0.004).stale.all()
    for servo in peer.servos:
        servo.silent_until = 0.0
    bus.clock.sleep(0.01)
    assert bus.read_state(bus.clock.now() + 0.02).all_fresh
    assert bus.stats.timeouts == 1 and bus.stats.host_timeouts == 0
    assert bus.stats.late_replies == 0
    # a held reply after that one is the host's, once, and only its own timeout
    transport.extra_delay_s = HELD_S
    assert bus.read_state(bus.clock.now() + 0.004).stale.all()
    bus.clock.sleep(0.01)
    assert bus.read_state(bus.clock.now() + 0.02).all_fresh
    bus.clock.sleep(0.01)
    assert bus.read_state(bus.clock.now() + 0.02).all_fresh
    assert (bus.stats.timeouts, bus.stats.host_timeouts) == (2, 1)


def _late_by(return_delay_us: int, room_s: float, late_s: float) -> int:
    """The host's timeouts after a read whose deadline leaves ``room_s`` past the reply's
    wire time, on servos commissioned with ``return_delay_us``, when the reply comes
    ``late_s`` after its wire time (and then in whole)."""
    rig = small_rig()
    rig = dataclasses.replace(rig, servo_settings=dataclasses.replace(
        rig.servo_settings, return_delay_us=return_delay_us))
    bus, transport, peer = _held_bus(rig)
    wire = bus.reader.read_wire_s(len(peer.servos))
    transport.extra_delay_s = late_s
    state = bus.read_state(bus.clock.now() + wire + room_s)
    assert state.sent and state.stale.all() and bus.stats.timeouts == 1
    bus.clock.sleep(0.005)
    assert bus.read_state(bus.clock.now() + 0.02).all_fresh
    return bus.stats.host_timeouts


def test_a_reply_a_servo_could_still_have_sent_stays_the_buss() -> None:
    """A deadline before the latest instant a servo could answer (its wire time, the Return
    Delay Time commissioning gave it, and HELD_MARGIN_S): a reply after it is no sign of
    the host; past that instant it is."""
    assert _late_by(0, 0.5 * HELD_MARGIN_S, HELD_MARGIN_S) == 0
    assert _late_by(0, 2 * HELD_MARGIN_S, 3 * HELD_MARGIN_S) == 1
    # servos set to answer 500 us late: the same wait is too short to tell
    assert _late_by(500, 2 * HELD_MARGIN_S, 3 * HELD_MARGIN_S) == 0
    assert _late_by(500, 0.0005 + 2 * HELD_MARGIN_S, 0.0005 + 3 * HELD_MARGIN_S) == 1


def test_the_loops_look_at_the_line_before_a_read_finds_a_held_reply() -> None:
    """The loop asks for the quiet wait before each read (``bus.quiet_wait_s()``), which
    drops what came late: a held reply is found there."""
    bus, transport, _ = _held_bus()
    transport.extra_delay_s = HELD_S
    assert bus.read_state(bus.clock.now() + 0.004).stale.all()
    bus.clock.sleep(0.01)
    bus.quiet_wait_s()
    assert (bus.stats.timeouts, bus.stats.host_timeouts, bus.stats.late_replies) == (1, 1, 1)


def test_a_newer_timeout_ends_the_look_for_an_older_ones_reply() -> None:
    """One servo: every read asks the same order. A silence, then a read whose deadline
    left a servo no room to be late: its reply, a little late, makes nothing the host's."""
    bus, transport, peer = _held_bus(small_rig(1))
    peer.servos[0].silent_until = math.inf
    assert bus.read_state(bus.clock.now() + 0.004).stale.all()
    peer.servos[0].silent_until = 0.0
    bus.clock.sleep(0.01)
    wire = bus.reader.read_wire_s(1)
    transport.extra_delay_s = 0.5 * HELD_MARGIN_S
    assert bus.read_state(bus.clock.now() + wire + 0.25 * HELD_MARGIN_S).stale.all()
    bus.clock.sleep(0.01)
    assert bus.read_state(bus.clock.now() + 0.02).all_fresh
    assert (bus.stats.timeouts, bus.stats.host_timeouts) == (2, 0)


class _Pressure(CpuPressure):
    """The host's CPU pressure, growing by ``step`` at each look."""

    def __init__(self) -> None:
        super().__init__("/nonexistent/pressure")
        self.step = 0
        self.total = 0

    def total_us(self) -> int | None:
        self.total += self.step
        return self.total


def test_a_held_reply_of_another_request_does_not_make_a_silence_the_hosts() -> None:
    bus, transport, peer = _held_bus()
    pressure = _Pressure()
    bus.link.pressure = pressure
    pressure.step = 10_000_000  # the host's tasks waited: this timeout is the host's at once
    transport.extra_delay_s = 0.015  # and its reply comes much later
    assert bus.read_state(bus.clock.now() + 0.004).stale.all()
    assert (bus.stats.timeouts, bus.stats.host_timeouts) == (1, 1)
    pressure.step = 0
    for servo in peer.servos:
        servo.silent_until = math.inf  # the next read is lost on the bus
    assert bus.read_state(bus.clock.now() + 0.004).stale.all()
    for servo in peer.servos:
        servo.silent_until = 0.0
    # the first read's reply comes ahead of the third's: not the silent read's
    assert bus.read_state(bus.clock.now() + 0.3).all_fresh
    assert bus.stats.late_replies == 1
    assert (bus.stats.timeouts, bus.stats.host_timeouts) == (2, 1)


def test_a_timeout_the_host_made_at_once_is_counted_once_when_its_reply_comes() -> None:
    bus, transport, _ = _held_bus()
    pressure = _Pressure()
    bus.link.pressure = pressure
    pressure.step = 10_000_000
    transport.extra_delay_s = HELD_S
    assert bus.read_state(bus.clock.now() + 0.004).stale.all()
    pressure.step = 0
    assert (bus.stats.timeouts, bus.stats.host_timeouts) == (1, 1)
    bus.clock.sleep(0.01)
    assert bus.read_state(bus.clock.now() + 0.02).all_fresh
    assert (bus.stats.timeouts, bus.stats.host_timeouts) == (1, 1)


def test_the_awaited_reply_is_looked_for_until_the_next_requests_reply_only() -> None:
    bus, _, _ = _held_bus()
    link = bus.link
    reply = b"the reply"
    link.timed_out(bus.clock.now(), lambda data: reply in data)
    link.send(b"\xff\xff\xfd\x00next", answered=False)  # a goal write: no reply, no count
    link.send(b"\xff\xff\xfd\x00next")  # the next request: the reply may come ahead of it
    link.late_reply_came(b"another")
    assert bus.stats.host_timeouts == 0
    link.late_reply_came(reply)
    assert bus.stats.host_timeouts == 1
    link.late_reply_came(reply)  # once only
    assert bus.stats.host_timeouts == 1
    link.timed_out(bus.clock.now(), lambda data: reply in data)
    link.send(b"\xff\xff\xfd\x00next")
    link.send(b"\xff\xff\xfd\x00next")  # a second request: the first's reply is done with
    link.late_reply_came(reply)
    assert bus.stats.host_timeouts == 1
    link.timed_out(bus.clock.now(), lambda data: reply in data)
    link.timed_out(bus.clock.now(), None)  # a newer timeout, its reply no sign of the host
    link.late_reply_came(reply)  # (a reply like the older one's: one servo, one order)
    assert bus.stats.host_timeouts == 1
    link.timed_out(bus.clock.now(), lambda data: reply in data)
    link.timed_out(bus.clock.now() - 2 * HOST_STALL_S)  # the host's at once: woke late
    assert bus.stats.host_timeouts == 2
    link.late_reply_came(reply)  # the older one is no longer looked for either
    assert bus.stats.host_timeouts == 2


def test_a_reply_to_another_request_or_a_damaged_one_does_not_count() -> None:
    bus, transport, _ = _held_bus()
    transport.extra_delay_s = HELD_S
    assert bus.read_state(bus.clock.now() + 0.004).stale.all()
    link = bus.link
    assert link._awaited is not None
    good = bytes(transport._arrivals[0][1])
    assert link._awaited(good) and link._awaited(b"\x00\x01" + good + b"\xff")
    damaged = bytearray(good)
    damaged[len(good) // 2] ^= 0x40  # a flipped bit in one servo's block: its CRC fails
    assert not link._awaited(bytes(damaged))
    assert not link._awaited(good[:-3])  # cut short
    # the same servos asked in another order: the same reply is not theirs
    fast = bus.reader.fast
    asked = transport.writes[-1]
    mine = next(o for o in fast.orders if o.ids.tobytes() in asked)
    other = next(o for o in fast.orders if o is not mine and sorted(o.ids) == sorted(mine.ids))

    def test_of(order: Order) -> Callable[[bytes], bool]:
        link.all_heard()  # (a request already asked and unheard gets no test)
        held = link.held_test(order.indices, order.ids.tobytes(), fast.plan.data_len,
                              len(good), math.inf)
        assert held is not None
        return held

    assert test_of(mine)(good)
    assert not test_of(other)(good)
    # what came late is kept up to a bound: past it, nothing more is kept or looked at
    link._late += bytes(LATE_LOOK_BYTES)
    bus.clock.sleep(0.02)
    assert bus.read_state(bus.clock.now() + 0.02).all_fresh
    assert len(link._late) == LATE_LOOK_BYTES and bus.stats.host_timeouts == 0
    assert bus.read_state(bus.clock.now() + 0.02).all_fresh
    assert not link._late and link._awaited is None  # done with at the second request


def test_a_servo_left_out_at_start_up_may_still_answer_at_the_factorys_delay() -> None:
    """A servo left out at connect (silent then) is not commissioned until it is admitted,
    so it may still answer 500 us late (the factory's Return Delay Time): a read asking
    only it, whose deadline falls before the protocol's longest delay, does not make its
    normal reply the host's. A commissioned servo (delay 0) read so is the host's."""
    rig = small_rig()
    peer = PeerBus(rig)
    late = peer.servos[-1]
    late.silent_until = math.inf
    bus, transport, _ = make_bus(rig, peer=peer, temperature_every=0, reply_timeout_s=0.01,
                                 fault_policy=FaultPolicy(read_retries=0), missing_ok=True)
    assert bus.left_out == (len(peer.servos) - 1,)
    late.silent_until = 0.0  # plugged back in, still at the factory's delay (the fake
    # transport delivers at wire time: extra_delay_s below stands for that delay)
    fast = bus.reader.fast

    def host_after(index: int, held_s: float) -> int:
        before = bus.stats.host_timeouts
        order = fast._order_of(np.array([index]))
        transport.extra_delay_s = held_s
        # 0.4 ms past the reply's wire time, from when the line lets the request out
        start = bus.link.request_start(bus.clock.now())
        assert fast.read(order.indices, start + bus.reader.read_wire_s(1) + 0.4e-3) == NONE
        bus.clock.sleep(0.01)  # the reply has come in whole
        bus.quiet_wait_s()
        return bus.stats.host_timeouts - before

    assert host_after(len(peer.servos) - 1, 0.5e-3) == 0  # its own 500 us: a servo's timing
    assert host_after(0, 0.5e-3) == 1  # a commissioned servo's reply held as long: the host's


def test_a_register_sweeps_held_reply_is_the_hosts_too() -> None:
    """The housekeeping reads (temperatures, Bus Watchdogs: one byte of every servo in one
    Fast Sync Read) follow the same rule as the state reads."""
    bus, transport, peer = _held_bus()
    transport.extra_delay_s = HELD_S
    assert all(v is None for v in bus.sweep.read(Reg.PRESENT_TEMPERATURE,
                                                 bus.clock.now() + 0.004))
    assert (bus.stats.timeouts, bus.stats.host_timeouts) == (1, 0)
    bus.clock.sleep(0.01)
    bus.quiet_wait_s()
    assert (bus.stats.timeouts, bus.stats.host_timeouts, bus.stats.late_replies) == (1, 1, 1)
    # nobody answering stays the bus's
    for servo in peer.servos:
        servo.silent_until = math.inf
    assert all(v is None for v in bus.sweep.read(Reg.PRESENT_TEMPERATURE,
                                                 bus.clock.now() + 0.004))
    bus.clock.sleep(0.01)
    bus.quiet_wait_s()
    assert (bus.stats.timeouts, bus.stats.host_timeouts) == (2, 1)
    # and a reply that comes in time counts nothing
    for servo in peer.servos:
        servo.silent_until = 0.0
    assert bus.link._unheard  # (the silent sweep's request: not to be credited again)
    assert None not in bus.sweep.read(Reg.PRESENT_TEMPERATURE, bus.clock.now() + 0.004)
    assert (bus.stats.timeouts, bus.stats.host_timeouts) == (2, 1)
    assert not bus.link._unheard  # a whole reply: no earlier one can still be on its way


def test_one_sweeps_held_reply_does_not_make_the_next_sweeps_silence_the_hosts() -> None:
    """The Bus Watchdog sweep and the temperature sweep run back to back and their one-byte
    replies do not say which item they hold: each sweep asks the servos in another order,
    so a late reply of the one before is not taken for the next one's (neither as its
    values nor as its held reply)."""
    bus, transport, peer = _held_bus()
    transport.extra_delay_s = 0.012  # the watchdog sweep's reply, held past the next sweep
    assert all(v is None for v in bus.sweep.read(Reg.BUS_WATCHDOG, bus.clock.now() + 0.004))
    for servo in peer.servos:
        servo.silent_until = math.inf  # the temperature sweep's own reply is lost on the bus
    assert all(v is None for v in bus.sweep.read(Reg.PRESENT_TEMPERATURE,
                                                 bus.clock.now() + 0.004))
    bus.clock.sleep(0.03)
    bus.quiet_wait_s()
    # the second timeout is the bus's; the first one's look ended with it (undercount)
    assert (bus.stats.timeouts, bus.stats.host_timeouts) == (2, 0)
    asked = [w for w in transport.writes if w[7] == 0x8A][-2:]  # the two sweeps' requests
    assert asked[0][12:-2] != asked[1][12:-2]  # (their IDs, in another order)
    # a watchdog sweep's reply that comes within the temperature sweep's wait is not read
    # as temperatures
    for servo in peer.servos:
        servo.silent_until = 0.0
    transport.extra_delay_s = 0.006
    assert all(v is None for v in bus.sweep.read(Reg.BUS_WATCHDOG, bus.clock.now() + 0.004))
    for servo in peer.servos:
        servo.silent_until = math.inf
    assert all(v is None for v in bus.sweep.read(Reg.PRESENT_TEMPERATURE,
                                                 bus.clock.now() + 0.02))


def test_a_sweeps_deadline_before_a_servos_latest_answer_leaves_its_timeout_the_buss() -> None:
    def host_after(room_s: float, late_s: float) -> int:
        bus, transport, peer = _held_bus()
        n = len(peer.servos)
        wire = (codec.fast_reply_len(1, n) + 14 + n) * bus.link.budget.byte_s
        transport.extra_delay_s = late_s
        start = bus.link.request_start(bus.clock.now())
        assert None in bus.sweep.read(Reg.PRESENT_TEMPERATURE, start + wire + room_s)
        bus.clock.sleep(0.01)
        bus.quiet_wait_s()
        assert bus.stats.timeouts == 1
        return bus.stats.host_timeouts

    assert host_after(0.5 * HELD_MARGIN_S, HELD_MARGIN_S) == 0
    assert host_after(2 * HELD_MARGIN_S, 3 * HELD_MARGIN_S) == 1


def test_a_sweep_that_heard_part_of_its_reply_gives_no_held_test() -> None:
    """A sweep that heard nothing leaves its held test; the next sweep, cut short (some
    servo answered), must not hand that test on with its own timeout."""
    bus, transport, peer = _held_bus()
    transport.extra_delay_s = HELD_S
    assert all(v is None for v in bus.sweep.read(Reg.PRESENT_TEMPERATURE,
                                                 bus.clock.now() + 0.004))
    assert bus.link._awaited is not None
    bus.clock.sleep(0.01)
    bus.quiet_wait_s()
    assert bus.stats.host_timeouts == 1
    peer.servos[-1].silent_until = math.inf  # a reply cut short at one servo
    values = bus.sweep.read(Reg.PRESENT_TEMPERATURE, bus.clock.now() + 0.004)
    assert None in values and any(v is not None for v in values)
    assert bus.stats.timeouts == 2 and bus.link._awaited is None


def _two_servo_bus() -> tuple[DynamixelBus, EmulatorTransport, PeerBus]:
    return make_bus(small_rig(2), temperature_every=0, reply_timeout_s=0.01,
                    fault_policy=FaultPolicy(read_retries=0))


def test_a_request_asked_again_while_unheard_gets_no_held_test() -> None:
    """Two servos have two orders: sweeps (and state reads) go A, B, A. When A's reply is
    held past B and A again, and those two heard nothing because the servos stopped
    answering, A's late reply would pass the second A's test: the second ask of the
    same servos in the same order, unheard since the last whole reply, gets none."""
    bus, transport, peer = _two_servo_bus()
    transport.extra_delay_s = 0.02
    bus.sweep.read(Reg.BUS_WATCHDOG, bus.clock.now() + 0.004)
    for servo in peer.servos:
        servo.silent_until = math.inf
    for _ in range(2):
        bus.sweep.read(Reg.BUS_WATCHDOG, bus.clock.now() + 0.004)
    bus.clock.sleep(0.05)
    bus.quiet_wait_s()
    assert (bus.stats.timeouts, bus.stats.host_timeouts) == (3, 0)

    bus, transport, peer = _two_servo_bus()
    transport.extra_delay_s = 0.02
    assert bus.read_state(bus.clock.now() + 0.004).stale.all()
    for servo in peer.servos:
        servo.silent_until = math.inf
    for _ in range(2):
        bus.clock.sleep(0.001)
        assert bus.read_state(bus.clock.now() + 0.004).stale.all()
    bus.clock.sleep(0.05)
    bus.quiet_wait_s()
    assert bus.stats.timeouts == 3 and bus.stats.host_timeouts == 0
    # a whole reply in time clears what was unheard: the rule applies again after it
    for servo in peer.servos:
        servo.silent_until = 0.0
    assert bus.read_state(bus.clock.now() + 0.02).all_fresh
    transport.extra_delay_s = HELD_S
    assert bus.read_state(bus.clock.now() + 0.004).stale.all()
    bus.clock.sleep(0.01)
    bus.quiet_wait_s()
    assert bus.stats.host_timeouts == 1


def test_a_turned_sweep_still_gives_each_servos_value_at_its_rig_index() -> None:
    bus, transport, peer = _held_bus()
    for k, servo in enumerate(peer.servos):
        servo.warm_to(30 + k)
    want = [30 + k for k in range(len(peer.servos))]
    asked = set()
    for _ in range(8):
        assert bus.sweep.read(Reg.PRESENT_TEMPERATURE, bus.clock.now() + 0.004) == want
        asked.add(transport.writes[-1][12:-2])
    assert len(asked) == len(peer.servos)  # every turn of the order was asked
