"""The emulated bus polls for a back-to-back client's next request, and only for it.

After a reply, a client whose last ``REQUEST_POLL_STREAK`` requests each came within
``REQUEST_POLL_S`` of the reply before is polled for (the bus thread does not go to
sleep on the line); one that pauses between requests, or every few, is waited for
asleep, at no CPU. Either way a reply leaves no
earlier than the wire could carry the request and the reply.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

from sim.dxl_bus import BITS_PER_BYTE, SimBus
from sim.dxl_servo import EmulatedServo

BAUD = 4_000_000
PING_BYTES = 10 + 14  # the instruction and the servo's status


@pytest.fixture
def bus() -> Iterator[SimBus]:
    with SimBus([EmulatedServo(i, baud=BAUD) for i in (1, 2)], wire_timing=True) as b:
        yield b


def _open(bus: SimBus) -> tuple[PortHandler, PacketHandler]:
    port = PortHandler(bus.port_path)
    assert port.openPort()
    assert port.setBaudRate(BAUD)
    return port, PacketHandler(2.0)


def test_a_client_cycling_back_to_back_is_polled_for_and_never_answered_early(
        bus: SimBus) -> None:
    port, ph = _open(bus)
    wire_s = PING_BYTES * BITS_PER_BYTE / BAUD
    rounds = []
    try:
        for _ in range(300):
            t0 = time.perf_counter()
            model, result, error = ph.ping(port, 2)
            rounds.append(time.perf_counter() - t0)
            assert (model, result, error) == (1200, COMM_SUCCESS, 0)
    finally:
        port.closePort()
    assert bus.request_polls > 0
    assert bus.request_poll_hits > 0
    # the wire model still holds: no reply before the request and it were on the wire
    assert min(rounds) >= wire_s


def test_a_client_that_pauses_between_requests_is_waited_for_asleep(bus: SimBus) -> None:
    port, ph = _open(bus)
    try:
        for _ in range(20):
            assert ph.ping(port, 1)[1] == COMM_SUCCESS
            time.sleep(0.003)  # 200 Hz-like: far longer than the poll window
    finally:
        port.closePort()
    assert bus.request_polls == 0
    assert bus.request_poll_hits == 0


def test_quick_requests_that_pause_every_few_are_not_polled_for(bus: SimBus) -> None:
    """Two hands' loops on one bus: a request now and then follows the other hand's
    reply at once, but every cycle has a pause; the bus thread never spins for them."""
    port, ph = _open(bus)
    try:
        for _ in range(10):
            for _ in range(4):  # fewer than REQUEST_POLL_STREAK in a row
                assert ph.ping(port, 1)[1] == COMM_SUCCESS
            time.sleep(0.003)
    finally:
        port.closePort()
    assert bus.request_polls == 0
