"""An ID write and a Factory Reset, driven by the real dynamixel-sdk as set-up tools do.

A servo answers a packet from the ID that packet addressed, then takes its new ID
(issue 38): the SDK accepts only a status from the ID it asked, so a tool that
writes register 7 with ``write1ByteTxRx`` (as LeRobot's motor set-up does) or
calls ``factoryReset`` (as ORCA's reset does) must see success, and find the servo
at its new ID afterwards.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator

import pytest
from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

from firmware_protocol.dynamixel import Reg
from sim.dxl_bus import SimBus
from sim.dxl_servo import REBOOT_S, EmulatedServo


@pytest.fixture
def sdk() -> Iterator[tuple[SimBus, PortHandler, PacketHandler]]:
    # the SDK busy-polls for the reply in this interpreter, which the emulator's thread
    # shares: hand the GIL over every 0.1 ms, not every 5 ms (its ~34 ms timeout at
    # 1 Mbps is otherwise spent waiting for the interpreter on a loaded machine)
    interval_s = sys.getswitchinterval()
    sys.setswitchinterval(1e-4)
    with SimBus([EmulatedServo(1), EmulatedServo(4)]) as bus:
        port = PortHandler(bus.port_path)
        assert port.openPort() and port.setBaudRate(1_000_000)
        try:
            yield bus, port, PacketHandler(2.0)
        finally:
            port.closePort()
            sys.setswitchinterval(interval_s)


def test_id_write_answers_from_the_old_id_then_the_servo_answers_at_the_new(
    sdk: tuple[SimBus, PortHandler, PacketHandler],
) -> None:
    bus, port, pk = sdk
    result, error = pk.write1ByteTxRx(port, 4, Reg.ID, 9)
    assert (result, error) == (COMM_SUCCESS, 0), pk.getTxRxResult(result)
    assert bus.servo(9).id == 9
    model, result, error = pk.ping(port, 9)
    assert (result, error) == (COMM_SUCCESS, 0) and model == 1200
    _, result, _ = pk.ping(port, 4)
    assert result != COMM_SUCCESS  # nobody answers at the old ID any more
    # the servo at the new ID reads back its ID, as a set-up tool checks it
    value, result, error = pk.read1ByteTxRx(port, 9, Reg.ID)
    assert (value, result, error) == (9, COMM_SUCCESS, 0)


@pytest.mark.parametrize(("option", "new_id", "new_baud_index"),
                         [(0xFF, 1, 1), (0x01, 4, 1), (0x02, 4, 3)])
def test_factory_reset_answers_from_the_id_it_was_sent_to(
    sdk: tuple[SimBus, PortHandler, PacketHandler], option: int, new_id: int,
    new_baud_index: int,
) -> None:
    bus, port, pk = sdk
    if option == 0xFF:  # the reset servo takes ID 1: servo 1 moves out of its way first
        assert pk.write1ByteTxRx(port, 1, Reg.ID, 2) == (COMM_SUCCESS, 0)
    servo = bus.servo(4)
    result, error = pk.factoryReset(port, 4, option)
    assert (result, error) == (COMM_SUCCESS, 0), pk.getTxRxResult(result)
    assert servo.id == new_id and servo.mem[Reg.BAUD_RATE] == new_baud_index
    time.sleep(REBOOT_S * 1.5)  # the servo is silent while it restarts
    if new_baud_index != 3:  # now at 57600: the client follows
        assert port.setBaudRate(57_600)
    model, result, error = pk.ping(port, new_id)
    assert (result, error) == (COMM_SUCCESS, 0) and model == 1200
