"""A read timeout whose reply still comes in whole is the host's (``BusStats.host_timeouts``):
a servo answers within its Return Delay Time or not at all, so a whole, intact reply that
arrives after its deadline was held on its way (the host, an emulator, a USB adapter), not
lost on the bus. Nothing heard at all, or a reply cut short, stays the bus's.

The real driver on the in-process emulator through a fake transport on a FakeClock (the
process never wakes late and no CPU pressure is looked at): the compute-only lane.
"""

from __future__ import annotations

import math

from handrig.devices.servo import DynamixelBus, FaultPolicy
from handrig.devices.servo.link import LATE_LOOK_BYTES
from tests.handrig.devices.servo.servo_fakes import EmulatorTransport, PeerBus
from tests.helpers.servos import make_bus, small_rig

HELD_S = 0.006  # the reply comes this long after its wire time: after its read gave up


def _held_bus() -> tuple[DynamixelBus, EmulatorTransport, PeerBus]:
    return make_bus(small_rig(), temperature_every=0, reply_timeout_s=0.01,
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
    assert len(good) < LATE_LOOK_BYTES
    # a read of other servos: the same reply is not theirs
    other = bus.reader.fast._whole_reply(bytes([1, 2]), len(good))
    assert not other(good)
