"""A read timeout the host made (``BusStats.host_timeouts``): when this process only wakes
1 ms or more after the reply's deadline (the VM was descheduled, a host stall), the
reply's writer was most likely held too, and the timeout is the host's, not the bus's:
counted apart and said so in the summary's fault line, once, not per servo.

The real driver on the in-process emulator through a fake transport whose waits can end
late (a scripted host stall), on a FakeClock: the compute-only lane.
"""

from __future__ import annotations

import math

from handrig.app.summary import bus_faults
from handrig.clock import FakeClock
from handrig.devices.servo import DynamixelBus
from handrig.devices.servo.link import HOST_STALL_S
from tests.handrig.devices.servo.servo_fakes import EmulatorTransport, PeerBus
from tests.helpers.servos import BAUD, small_rig


class StallingTransport(EmulatorTransport):
    """A wait that finds no reply by its deadline ends ``stall_s`` after it."""

    stall_s = 0.0

    def _receive(self, deadline_s: float, spin_from_s: float | None,
                 spin_until_s: float) -> bytes:
        got = super()._receive(deadline_s, spin_from_s, spin_until_s)
        if not got and self.stall_s:
            self.fake_clock.advance(self.stall_s)
        return got


def _bus() -> tuple[DynamixelBus, StallingTransport, PeerBus]:
    rig = small_rig()
    clock = FakeClock(100.0)
    peer = PeerBus(rig, None)
    transport = StallingTransport(peer, clock, BAUD)
    bus = DynamixelBus("fake:emulator", rig, baud=BAUD, clock=clock, transport=transport)
    bus.connect()
    return bus, transport, peer


def test_a_timeout_the_host_held_this_process_through_is_the_hosts() -> None:
    bus, transport, peer = _bus()
    assert bus.read_state().all_fresh
    for servo in peer.servos:
        servo.silent_until = math.inf  # nobody answers
    transport.stall_s = 0.0  # woke at the deadline: the bus's silence, not the host's
    bus.read_state()
    timeouts = bus.stats.timeouts
    assert timeouts >= 1 and bus.stats.host_timeouts == 0
    transport.stall_s = HOST_STALL_S + 0.0005  # woke 1.5 ms late: the host held us
    bus.read_state()
    assert bus.stats.timeouts > timeouts
    assert bus.stats.host_timeouts == bus.stats.timeouts - timeouts
    transport.stall_s = 0.8 * HOST_STALL_S  # a little late: not a stall
    before = bus.stats.host_timeouts
    bus.read_state()
    assert bus.stats.host_timeouts == before
    # the summary's fault line names them apart, once
    words = bus_faults({"timeouts": bus.stats.timeouts,
                        "host_timeouts": bus.stats.host_timeouts})
    assert list(words.values()) == [bus.stats.timeouts, bus.stats.host_timeouts]
    assert "the host's" in list(words)[1]
    assert f"the host's {bus.stats.host_timeouts}" in bus.stats.summary()
