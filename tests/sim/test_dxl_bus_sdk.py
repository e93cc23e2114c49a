"""The emulated bus, driven by the real dynamixel-sdk over a pty."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import pytest
from dynamixel_sdk import (
    COMM_RX_CORRUPT,
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupBulkRead,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)

from firmware_protocol.dynamixel import ErrorCode, HardwareError
from sim.dxl_bus import FaultSpec, SimBus
from sim.dxl_servo import EmulatedServo

IDS = (1, 2, 3, 5)


def _eventually(pred: Callable[[], bool], timeout_s: float = 2.0) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.002)
    return pred()


@pytest.fixture
def bus() -> Iterator[SimBus]:
    with SimBus([EmulatedServo(i) for i in IDS]) as b:
        yield b


def _open(bus: SimBus, baud: int = 1_000_000) -> tuple[PortHandler, PacketHandler]:
    port = PortHandler(bus.port_path)
    assert port.openPort()
    assert port.setBaudRate(baud)
    return port, PacketHandler(2.0)


def test_ping_broadcast_ping_and_model(bus: SimBus) -> None:
    port, ph = _open(bus)
    try:
        assert ph.ping(port, 2) == (1200, COMM_SUCCESS, 0)
        found, result = ph.broadcastPing(port)
        assert result == COMM_SUCCESS
        assert found == {i: [1200, 46] for i in IDS}
        assert ph.read2ByteTxRx(port, 5, 0) == (1200, COMM_SUCCESS, 0)
        _, result, _ = ph.ping(port, 4)
        assert result == COMM_RX_TIMEOUT
    finally:
        port.closePort()


def test_sync_write_then_fast_sync_read_sync_read_bulk_read(bus: SimBus) -> None:
    port, ph = _open(bus)
    try:
        for i in IDS:
            assert ph.write1ByteTxRx(port, i, 64, 1) == (COMM_SUCCESS, 0)
        sw = GroupSyncWrite(port, ph, 116, 4)
        for i in IDS:
            sw.addParam(i, (2048 + 10 * i).to_bytes(4, "little"))
        assert sw.txPacket() == COMM_SUCCESS
        # sync write gets no reply: wait for the bus thread to take it
        want = [2048 + 10 * i for i in IDS]
        assert _eventually(lambda: [bus.servo(i).goal for i in IDS] == want)
        # servos move at the velocity limit (~7000 ticks/s): 50 ticks take < 10 ms
        assert _eventually(lambda: [bus.servo(i).present for i in IDS] == want)
        fsr = GroupSyncRead(port, ph, 132, 4)
        for i in IDS:
            fsr.addParam(i)
        assert fsr.fastSyncRead() == COMM_SUCCESS
        assert [fsr.getData(i, 132, 4) for i in IDS] == [2048 + 10 * i for i in IDS]
        assert fsr.txRxPacket() == COMM_SUCCESS  # plain sync read
        assert [fsr.getData(i, 132, 4) for i in IDS] == [2048 + 10 * i for i in IDS]
        br = GroupBulkRead(port, ph)
        assert br.addParam(1, 132, 4) and br.addParam(3, 0, 2) and br.addParam(5, 64, 1)
        assert br.txRxPacket() == COMM_SUCCESS
        assert br.getData(1, 132, 4) == 2058
        assert br.getData(3, 0, 2) == 1200
        assert br.getData(5, 64, 1) == 1
        assert br.fastBulkRead() == COMM_SUCCESS  # Fast Bulk Read: one combined reply
        assert br.getData(1, 132, 4) == 2058
        assert br.getData(3, 0, 2) == 1200
        assert br.getData(5, 64, 1) == 1
    finally:
        port.closePort()


def test_errors_as_a_servo_reports_them(bus: SimBus) -> None:
    port, ph = _open(bus)
    try:
        # read-only item
        assert ph.write2ByteTxRx(port, 1, 0, 7) == (COMM_SUCCESS, ErrorCode.ACCESS)
        # EEPROM with torque on
        assert ph.write1ByteTxRx(port, 1, 64, 1) == (COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, 1, 9, 0) == (COMM_SUCCESS, ErrorCode.ACCESS)
        assert ph.write1ByteTxRx(port, 1, 64, 0) == (COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, 1, 9, 0) == (COMM_SUCCESS, 0)
        assert bus.servo(1).return_delay_s == 0
        # out of range, cut item, position limit
        assert ph.write1ByteTxRx(port, 1, 11, 2) == (COMM_SUCCESS, ErrorCode.DATA_RANGE)
        assert ph.write2ByteTxRx(port, 1, 116, 100) == (COMM_SUCCESS, ErrorCode.DATA_LENGTH)
        assert ph.write4ByteTxRx(port, 1, 116, 5000) == (COMM_SUCCESS, ErrorCode.DATA_LIMIT)
        # action with nothing registered
        assert ph.action(port, 1) == COMM_SUCCESS  # the SDK does not wait for this status
    finally:
        port.closePort()


def test_overload_only_a_reboot_clears() -> None:
    faults = FaultSpec(overload=frozenset({2}))
    with SimBus([EmulatedServo(i) for i in IDS], faults=faults) as bus:
        port, ph = _open(bus)
        try:
            assert _eventually(lambda: bus.fault_counts["overload"] == 1)
            value, result, error = ph.read1ByteTxRx(port, 2, 70)
            assert (result, value) == (COMM_SUCCESS, HardwareError.OVERLOAD)
            assert error & 0x80
            assert ph.write1ByteTxRx(port, 2, 64, 1)[1] & 0x80
            assert not bus.servo(2).torque_enabled
            assert ph.reboot(port, 2)[0] == COMM_SUCCESS
            time.sleep(0.15)
            assert ph.read1ByteTxRx(port, 2, 70) == (0, COMM_SUCCESS, 0)
        finally:
            port.closePort()


def test_faults_are_counted_and_reach_the_client() -> None:
    faults = FaultSpec(corrupt=1.0, seed=3)
    with SimBus([EmulatedServo(1)], faults=faults) as bus:
        port, ph = _open(bus)
        try:
            _, result, _ = ph.ping(port, 1)
            assert result == COMM_RX_CORRUPT
            assert bus.fault_counts["corrupted"] == 1
        finally:
            port.closePort()


def test_fault_spec_parse() -> None:
    f = FaultSpec.parse("drop=0.1,delay=0.2:0.01,missing=7+9,overload=3@1.5,seed=4")
    assert f.drop == 0.1 and f.delay == 0.2 and f.delay_s == 0.01
    assert f.missing == {7, 9} and f.overload == {3} and f.overload_after_s == 1.5 and f.seed == 4
    from handrig.errors import ConfigError

    with pytest.raises(ConfigError, match="unknown fault"):
        FaultSpec.parse("explode=1")
    with pytest.raises(ConfigError, match="out of range"):
        FaultSpec.parse("drop=2")
