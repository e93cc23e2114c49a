"""The emulated bus at the byte level: a raw client (our codec, pyserial) checks framing,
error replies, fault switches and wire timing."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
import serial

from firmware_protocol import dynamixel as dx
from sim.dxl_bus import FaultSpec, SimBus
from sim.dxl_servo import EmulatedServo

INST = dx.Instruction


class RawClient:
    """Writes instruction packets, collects whatever comes back within a time window."""

    def __init__(self, path: str, baud: int = 1_000_000) -> None:
        self.ser = serial.Serial(path, baudrate=baud, timeout=0)

    def send(self, servo_id: int, inst: int, params: bytes = b"") -> None:
        self.ser.reset_input_buffer()
        self.ser.write(dx.build_instruction(servo_id, inst, params, do_stuff=False))

    def collect(self, want: int, timeout_s: float = 0.5) -> bytes:
        out = bytearray()
        end = time.monotonic() + timeout_s
        while len(out) < want and time.monotonic() < end:
            out += self.ser.read(want - len(out))
            time.sleep(0.0005)
        return bytes(out)

    def statuses(self, data: bytes) -> list[dx.StatusPacket]:
        out = []
        pos = 0
        while (found := dx.find_frame(data, pos)) is not None:
            out.append(dx.parse_status(data[found[0]:found[1]]))
            pos = found[1]
        return out

    def close(self) -> None:
        self.ser.close()


@pytest.fixture
def servos() -> list[EmulatedServo]:
    return [EmulatedServo(i) for i in (1, 2, 3)]


def _bus(servos: list[EmulatedServo], **kw: object) -> Iterator[tuple[SimBus, RawClient]]:
    with SimBus(servos, **kw) as bus:  # type: ignore[arg-type]
        client = RawClient(bus.port_path)
        try:
            yield bus, client
        finally:
            client.close()


@pytest.fixture
def raw(servos: list[EmulatedServo]) -> Iterator[tuple[SimBus, RawClient]]:
    yield from _bus(servos)


def test_crc_error_and_unknown_instruction_get_error_status(raw: tuple[SimBus, RawClient]) -> None:
    bus, c = raw
    bad = bytearray(dx.build_instruction(2, INST.PING))
    bad[-1] ^= 0xFF
    c.ser.write(bytes(bad))
    (st,) = c.statuses(c.collect(11))
    assert (st.id, st.error_code) == (2, dx.ErrorCode.CRC)
    assert bus.stats.bad_crc == 1
    c.send(2, 0x77)
    (st,) = c.statuses(c.collect(11))
    assert st.error_code == dx.ErrorCode.INSTRUCTION


def test_read_of_stuffed_data_is_stuffed(raw: tuple[SimBus, RawClient]) -> None:
    _, c = raw
    # Goal PWM -1 then Goal Current -3: the bytes FF FF FD need stuffing in the reply
    value = bytes.fromhex("ff ff fd ff")
    c.send(1, INST.WRITE, dx.write_params(100, value))
    assert c.statuses(c.collect(11))[0].error == 0
    c.send(1, INST.READ, dx.read_params(100, 4))
    data = c.collect(16)
    assert len(data) == 16 and b"\xff\xff\xfd\xfd" in data[7:]
    (st,) = c.statuses(data)
    assert st.params == value


def test_status_return_level(raw: tuple[SimBus, RawClient]) -> None:
    bus, c = raw
    c.send(1, INST.WRITE, dx.write_params(68, b"\x01"))
    assert len(c.statuses(c.collect(11))) == 1
    c.send(1, INST.WRITE, dx.write_params(65, b"\x01"))  # LED: no status at level 1
    assert c.collect(11, 0.05) == b""
    assert bus.servo(1).get(dx.Reg.LED) == 1
    c.send(1, INST.READ, dx.read_params(65, 1))
    assert c.statuses(c.collect(12))[0].params == b"\x01"
    c.send(1, INST.WRITE, dx.write_params(68, b"\x00"))
    c.send(1, INST.READ, dx.read_params(65, 1))
    assert c.collect(12, 0.05) == b""
    c.send(1, INST.PING)
    assert len(c.statuses(c.collect(14))) == 1  # ping always answers


def test_bulk_write_fast_bulk_read_and_broadcast_action(raw: tuple[SimBus, RawClient]) -> None:
    bus, c = raw
    c.send(dx.BROADCAST_ID, INST.BULK_WRITE, dx.bulk_write_params(
        [(1, 65, b"\x01"), (3, 116, (3000).to_bytes(4, "little"))]))
    c.send(2, INST.REG_WRITE, dx.write_params(116, (1000).to_bytes(4, "little")))
    assert c.statuses(c.collect(11))[0].error == 0
    c.send(dx.BROADCAST_ID, INST.ACTION)
    time.sleep(0.02)
    assert bus.servo(1).get(dx.Reg.LED) == 1 and bus.servo(3).goal == 3000
    assert bus.servo(2).goal == 1000
    c.send(dx.BROADCAST_ID, INST.FAST_BULK_READ, dx.bulk_read_params([(3, 116, 4), (1, 0, 2)]))
    data = c.collect(8 + 8 + 6)
    parts = dx.parse_fast_read_reply(data, [4, 2])
    assert [(p.id, p.params) for p in parts] == [
        (3, (3000).to_bytes(4, "little")), (1, (1200).to_bytes(2, "little"))]


def test_missing_servo_cuts_fast_sync_read_short_and_is_counted(
        servos: list[EmulatedServo]) -> None:
    for bus, c in _bus(servos, faults=FaultSpec(missing=frozenset({2}))):
        c.send(dx.BROADCAST_ID, INST.FAST_SYNC_READ, dx.sync_read_params(132, 4, [1, 2, 3]))
        data = c.collect(8 + 3 * 8, 0.1)
        assert len(data) == 8 + 8  # servo 1's part, then nothing
        assert data[5] | data[6] << 8 == 1 + 3 * 8  # LEN announced the whole reply
        c.send(2, INST.PING)
        assert c.collect(14, 0.05) == b""
        assert bus.fault_counts["missing"] == 2
        assert bus.servo(2).id == 2  # still inspectable


@pytest.mark.parametrize("kind", ["drop", "corrupt", "wrong_id", "truncate", "delay"])
def test_reply_faults_are_applied_and_counted(servos: list[EmulatedServo], kind: str) -> None:
    faults = FaultSpec(**{kind: 1.0}, delay_s=0.05, seed=1)  # type: ignore[arg-type]
    for bus, c in _bus(servos, faults=faults):
        t0 = time.monotonic()
        c.send(1, INST.PING)
        data = c.collect(14, 0.3)
        elapsed = time.monotonic() - t0
        counted = {"drop": "dropped", "corrupt": "corrupted", "wrong_id": "wrong_id",
                   "truncate": "truncated", "delay": "delayed"}[kind]
        assert bus.fault_counts[counted] == 1
        if kind == "drop":
            assert data == b""
        elif kind == "corrupt":
            with pytest.raises(dx.PacketError):
                dx.parse_status(data)
        elif kind == "wrong_id":
            st = dx.parse_status(data)
            assert st.id != 1 and st.params[:2] == (1200).to_bytes(2, "little")
        elif kind == "truncate":
            assert 0 < len(data) < 14
        else:
            assert dx.parse_status(data).id == 1 and elapsed >= 0.05


def test_faults_repeat_with_the_same_seed(servos: list[EmulatedServo]) -> None:
    def run() -> list[int]:
        got = []
        fresh = [EmulatedServo(i) for i in (1, 2, 3)]
        for bus, c in _bus(fresh, faults=FaultSpec(drop=0.5, seed=7)):
            for k in range(20):
                c.send(1, INST.PING)
                # the emulator's own account of each ping (answered or dropped), so a
                # reply that a loaded host delivers late is not taken for a dropped one
                end = time.monotonic() + 5.0
                while (bus.stats.replies + bus.fault_counts["dropped"] <= k
                       and time.monotonic() < end):
                    time.sleep(0.001)
                answered = bus.stats.replies > len([n for n in got if n])
                got.append(len(c.collect(14, 5.0)) if answered else 0)
        return got

    first = run()
    assert first == run() and 0 in first and 14 in first


def test_wire_timing_reply_never_early(servos: list[EmulatedServo]) -> None:
    for s in servos:
        s.mem[9] = 0  # Return Delay Time 0
        s.mem[8] = 1  # Baud Rate 57600: a servo hears only its own rate
    servos[1].mem[9] = 100  # 200 us on servo 2
    for bus, c in _bus(servos, wire_timing=True):
        c.ser.baudrate = 57600  # 10 bits per byte: 174 us per byte
        byte_s = 10 / 57600
        params = dx.sync_read_params(132, 4, [1, 2, 3])
        packet = dx.build_instruction(dx.BROADCAST_ID, INST.FAST_SYNC_READ, params, do_stuff=False)
        c.ser.reset_input_buffer()
        t0 = time.perf_counter()
        c.ser.write(packet)
        data = c.collect(8 + 3 * 8, 1.0)
        elapsed = time.perf_counter() - t0
        assert len(data) == 32
        assert elapsed >= (len(packet) + len(data)) * byte_s
        # sync read: three replies, with servo 2's return delay
        packet = dx.build_instruction(dx.BROADCAST_ID, INST.SYNC_READ, params, do_stuff=False)
        c.ser.reset_input_buffer()
        t0 = time.perf_counter()
        c.ser.write(packet)
        data = c.collect(3 * 15, 1.0)
        elapsed = time.perf_counter() - t0
        assert [s.id for s in c.statuses(data)] == [1, 2, 3]
        assert elapsed >= (len(packet) + len(data)) * byte_s + 200e-6
        assert bus.baud() == 57600


def test_framing_survives_noise_and_a_corrupted_len(raw: tuple[SimBus, RawClient]) -> None:
    bus, c = raw
    ping = dx.build_instruction(3, INST.PING)
    c.ser.write(b"\x00\x01\xff" + ping)
    assert [s.id for s in c.statuses(c.collect(14))] == [3]
    # a header announcing 900 bytes that never come: after STALE_PARTIAL_S of waiting
    # while bytes keep arriving, the bus gives it up and answers the next packet
    c.ser.write(bytes.fromhex("ff ff fd 00 01 84 03 02"))
    answered = False
    end = time.monotonic() + 2.0
    while not answered and time.monotonic() < end:
        c.send(2, INST.PING)
        answered = bool(c.statuses(c.collect(14, 0.05)))
    assert answered
    assert bus.stats.noise_bytes >= 3


def test_check_baud_servo_hears_only_its_baud_rate() -> None:
    servos = [EmulatedServo(1, baud=1_000_000), EmulatedServo(2, baud=57_600)]
    for _, c in _bus(servos, check_baud=True):
        c.send(dx.BROADCAST_ID, INST.PING)
        assert [s.id for s in c.statuses(c.collect(28, 0.1))] == [1]
        c.ser.baudrate = 57_600
        c.send(dx.BROADCAST_ID, INST.PING)
        assert [s.id for s in c.statuses(c.collect(28, 0.1))] == [2]


def test_bus_watchdog_trips_when_the_host_goes_quiet(raw: tuple[SimBus, RawClient]) -> None:
    bus, c = raw
    c.send(1, INST.WRITE, dx.write_params(98, b"\x02"))  # 40 ms
    c.collect(11)
    c.send(1, INST.WRITE, dx.write_params(64, b"\x01"))
    c.collect(11)
    c.send(1, INST.WRITE, dx.write_params(116, (3000).to_bytes(4, "little")))
    assert c.statuses(c.collect(11))[0].error == 0
    end = time.monotonic() + 2.0
    while bus.servo(1).get(dx.Reg.BUS_WATCHDOG) != -1 and time.monotonic() < end:
        time.sleep(0.01)
    assert bus.servo(1).get(dx.Reg.BUS_WATCHDOG) == -1
    assert bus.servo(1).goal == bus.servo(1).present  # stopped where it was
    c.send(1, INST.WRITE, dx.write_params(116, (3000).to_bytes(4, "little")))
    assert c.statuses(c.collect(11))[0].error_code == dx.ErrorCode.DATA_RANGE


def test_each_sync_write_is_reported_with_its_receipt_time(servos: list[EmulatedServo]) -> None:
    seen: list[tuple[float, int, list[tuple[int, bytes]]]] = []
    for bus, client in _bus(servos):
        bus.on_sync_write = lambda t, a, items: seen.append((t, a, items))
        goals = [(1, 1000), (2, 2000), (3, 3000)]
        params = (116).to_bytes(2, "little") + (4).to_bytes(2, "little")  # Goal Position
        params += b"".join(bytes((i,)) + v.to_bytes(4, "little") for i, v in goals)
        sent = time.perf_counter()
        client.send(dx.BROADCAST_ID, dx.Instruction.SYNC_WRITE, params)
        end = time.monotonic() + 1.0
        while not seen and time.monotonic() < end:
            time.sleep(0.001)
    assert len(seen) == 1
    t, address, items = seen[0]
    assert address == 116 and sent <= t < sent + 0.5
    assert [(i, int.from_bytes(d, "little")) for i, d in items] == goals
