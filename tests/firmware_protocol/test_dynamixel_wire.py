"""Protocol 2.0 codec: golden bytes from the ROBOTIS e-manual, round trips, fuzz."""

from __future__ import annotations

import contextlib
import itertools

import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware_protocol import dynamixel as dx


def test_ping_crc_golden() -> None:
    # e-manual protocol2 ping example: CRC 19 4E.
    ping = dx.build_instruction(1, dx.Instruction.PING)
    assert ping == bytes.fromhex("ff ff fd 00 01 03 00 01 19 4e")
    assert dx.crc16(bytes.fromhex("ff ff fd 00 01 03 00 01")) == 0x4E19


@pytest.mark.parametrize(
    ("built", "golden"),
    [
        # ping reply of ID 1: model 1030 (0x0406), firmware 38
        (dx.build_status(1, 0, bytes((0x06, 0x04, 0x26))),
         "ff ff fd 00 01 07 00 55 00 06 04 26 65 5d"),
        # read Present Position (132, 4 bytes) of ID 1
        (dx.build_instruction(1, dx.Instruction.READ, dx.read_params(132, 4)),
         "ff ff fd 00 01 07 00 02 84 00 04 00 1d 15"),
        # write Goal Position 512 to ID 1
        (dx.build_instruction(1, dx.Instruction.WRITE,
                              dx.write_params(116, (512).to_bytes(4, "little"))),
         "ff ff fd 00 01 09 00 03 74 00 00 02 00 00 ca 89"),
    ],
)
def test_emanual_examples(built: bytes, golden: str) -> None:
    assert built == bytes.fromhex(golden)


def test_stuffing_adds_fd_and_crc_covers_stuffed_packet() -> None:
    params = bytes.fromhex("ff ff fd 01")
    packet = dx.build_status(3, 0, params)
    length = packet[5] | packet[6] << 8
    assert length == 2 + len(params) + 1 + 2  # 55 ERR params(+1 stuffed) CRC
    assert b"\xff\xff\xfd\xfd\x01" in packet
    assert dx.parse_status(packet) == dx.StatusPacket(3, 0, params)
    unstuffed = dx.build_instruction(3, 0x03, params, do_stuff=False)
    assert b"\xfd\xfd" not in unstuffed


def test_fast_sync_read_reply_layout() -> None:
    chunks = [(1, 0, bytes.fromhex("00 08 00 00")), (2, 0x80, bytes.fromhex("ff 07 00 00"))]
    packet = dx.build_fast_read_reply(chunks)
    # LEN = 1 + (data_len + 4) * N
    length = (1 + 8 * 2).to_bytes(2, "little")
    assert packet[:8] == bytes.fromhex("ff ff fd 00 fe") + length + b"\x55"
    assert len(packet) == 7 + 1 + 8 * 2
    # first chunk: ERR ID data CRC, the CRC being the running CRC from the header
    assert packet[8:10] == b"\x00\x01"
    assert packet[14:16] == dx.crc16(packet[:14]).to_bytes(2, "little")
    assert packet[16:18] == b"\x80\x02"
    # the last running CRC is the packet CRC
    assert packet[-2:] == dx.crc16(packet[:-2]).to_bytes(2, "little")
    parsed = dx.parse_fast_read_reply(packet, [4, 4])
    assert [(p.id, p.error, p.params) for p in parsed] == chunks
    broken = bytearray(packet)
    broken[14] ^= 1  # an intermediate CRC only a careful reader checks
    with pytest.raises(dx.PacketError) as exc:
        dx.parse_fast_read_reply(bytes(broken), [4, 4])
    assert exc.value.kind == "crc"


def test_find_frame_by_len() -> None:
    a = dx.build_instruction(1, dx.Instruction.PING)
    b = dx.build_instruction(2, dx.Instruction.READ, dx.read_params(132, 4))
    buf = b"\x00\x12" + a + b[:5]
    assert dx.find_frame(buf) == (2, 2 + len(a))
    assert dx.find_frame(buf, 2 + len(a)) is None
    assert dx.find_frame(buf + b[5:], 2 + len(a)) == (2 + len(a), 2 + len(a) + len(b))


def test_bad_crc_is_reported() -> None:
    packet = bytearray(dx.build_instruction(1, dx.Instruction.PING))
    packet[-1] ^= 0xFF
    with pytest.raises(dx.PacketError) as exc:
        dx.parse_instruction(bytes(packet))
    assert exc.value.kind == "crc"


def test_control_table_layout() -> None:
    table = dx.X_SERIES_TABLE
    assert table[dx.Reg.GOAL_POSITION].address == 116 and table[dx.Reg.GOAL_POSITION].size == 4
    assert table[dx.Reg.PRESENT_POSITION].address == 132
    assert table[dx.Reg.RETURN_DELAY_TIME].area is dx.Area.EEPROM
    assert table[dx.Reg.TORQUE_ENABLE].area is dx.Area.RAM
    assert table[dx.Reg.PRESENT_CURRENT].access is dx.Access.R
    for reg, item in table.items():
        assert item.address == int(reg)
        assert (item.area is dx.Area.EEPROM) == (item.address < dx.EEPROM_END)
    items = sorted(table.values(), key=lambda i: i.address)
    for a, b in itertools.pairwise(items):
        assert a.address + a.size <= b.address, (a, b)
    assert dx.MODELS["XL330-M288"].model_number == 1200
    assert dx.MODELS["XM430-W350"].model_number == 1020


@given(st.integers(0, 252), st.binary(max_size=200), st.integers(0, 0x7F))
def test_status_round_trip(servo_id: int, params: bytes, error: int) -> None:
    packet = dx.build_status(servo_id, error, params)
    assert dx.find_frame(packet) == (0, len(packet))
    assert dx.parse_status(packet) == dx.StatusPacket(servo_id, error, params)


@given(st.integers(0, 0xFE), st.integers(0, 255), st.binary(max_size=200))
def test_instruction_round_trip(servo_id: int, inst: int, params: bytes) -> None:
    if servo_id > 252 and servo_id != 0xFE:
        return
    packet = dx.build_instruction(servo_id, inst, params)
    assert dx.parse_instruction(packet) == dx.InstructionPacket(servo_id, inst, params)


@given(st.binary(max_size=64))
def test_stuff_round_trip(data: bytes) -> None:
    assert dx.unstuff(dx.stuff(data)) == data


@given(st.binary(max_size=300))
def test_parsers_never_crash_on_garbage(data: bytes) -> None:
    for parse in (dx.parse_instruction, dx.parse_status):
        with contextlib.suppress(dx.PacketError):
            parse(data)


def _crc_bitwise(data: bytes) -> int:
    crc = 0
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else crc << 1
            crc &= 0xFFFF
    return crc


@given(st.binary(max_size=80), st.binary(max_size=9))
def test_crc16_matches_bitwise_definition_and_continues(a: bytes, b: bytes) -> None:
    assert dx.crc16(a) == _crc_bitwise(a)
    assert dx.crc16(b, dx.crc16(a)) == _crc_bitwise(a + b)
