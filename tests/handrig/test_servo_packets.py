"""Packets of the servo driver: CRC against the SDK and the datasheet, framing, Fast Sync Read."""

from __future__ import annotations

import pytest
from dynamixel_sdk.protocol2_packet_handler import Protocol2PacketHandler
from hypothesis import given
from hypothesis import strategies as st

from handrig.errors import ProtocolError
from handrig.servo.packets import (
    build_instruction,
    crc16,
    fast_sync_valid,
    parse_status,
    stuff,
    unstuff,
)
from handrig.servo.registers import Reg, describe_hardware_error, describe_status_error

SDK = Protocol2PacketHandler()


def sdk_crc(data: bytes, crc: int = 0) -> int:
    return int(SDK.updateCRC(crc, list(data), len(data)))


def test_crc_golden_ping() -> None:
    # REFERENCE.md section 1: ping of ID 1 has CRC 19 4E (low byte first)
    assert build_instruction(1, 0x01) == bytes.fromhex("FF FF FD 00 01 03 00 01 19 4E")


@given(st.binary(max_size=300), st.integers(0, 0xFFFF))
def test_crc_equals_sdk(data: bytes, start: int) -> None:
    assert crc16(data, start) == sdk_crc(data, start)


@given(st.binary(max_size=64))
def test_stuffing_round_trip(body: bytes) -> None:
    stuffed = stuff(body)
    assert unstuff(stuffed) == body
    assert b"\xff\xff\xfd" not in stuffed.replace(b"\xff\xff\xfd\xfd", b"")


def test_instruction_is_stuffed() -> None:
    pkt = build_instruction(3, 0x03, bytes([0x74, 0x00, 0xFF, 0xFF, 0xFD, 0x00]))
    assert pkt[5] == 3 + 7  # LEN grew by one for the stuffed FD
    assert b"\xff\xff\xfd\xfd" in pkt[7:]
    assert pkt[-2] | pkt[-1] << 8 == sdk_crc(pkt[:-2])


def status(servo_id: int, err: int, params: bytes) -> bytes:
    length = len(params) + 4
    head = bytes([0xFF, 0xFF, 0xFD, 0x00, servo_id, length & 0xFF, length >> 8, 0x55, err])
    crc = sdk_crc(head + params)
    return head + params + bytes([crc & 0xFF, crc >> 8])


def test_parse_status_and_errors() -> None:
    s = parse_status(status(7, 0x80, b"\x01\x02"))
    assert (s.servo_id, s.error, s.params) == (7, 0x80, b"\x01\x02")
    bad = bytearray(status(7, 0, b"\x01\x02"))
    bad[-1] ^= 0xFF
    with pytest.raises(ProtocolError, match="CRC"):
        parse_status(bytes(bad))
    with pytest.raises(ProtocolError, match="shorter"):
        parse_status(status(7, 0, b"")[:9])
    with pytest.raises(ProtocolError, match="LEN"):
        parse_status(status(7, 0, b"\x01\x02") + b"\x00")


def fast_reply(blocks: list[tuple[int, int, bytes]]) -> bytes:
    """A Fast Sync Read reply built with the SDK's CRC: running CRC per servo block."""
    data_len = len(blocks[0][2])
    length = 1 + (data_len + 4) * len(blocks)
    out = bytearray([0xFF, 0xFF, 0xFD, 0x00, 0xFE, length & 0xFF, length >> 8, 0x55])
    for err, sid, data in blocks:
        out += bytes([err, sid]) + data
        crc = sdk_crc(bytes(out))
        out += bytes([crc & 0xFF, crc >> 8])
    return bytes(out)


def test_fast_sync_valid_per_servo() -> None:
    ids = (3, 7, 4)
    raw = fast_reply([(0, 3, b"\x00\x08\x00\x00"), (0x80, 7, b"\x10\x00\x00\x00"),
                      (0, 4, b"\xff\x0f\x00\x00")])
    out = [False] * 3
    fast_sync_valid(raw, ids, 4, out)
    assert out == [True, True, True]
    # truncated in the last block: the first two still verify
    fast_sync_valid(raw[:-3], ids, 4, out)
    assert out == [True, True, False]
    # corrupted data of the second servo: it and every later block fail (running CRC)
    bad = bytearray(raw)
    bad[8 + 8 + 3] ^= 0x01
    fast_sync_valid(bytes(bad), ids, 4, out)
    assert out == [True, False, False]
    # a block naming the wrong servo is not accepted for the one asked
    fast_sync_valid(raw, (3, 8, 4), 4, out)
    assert out == [True, False, True]
    fast_sync_valid(b"\xff\xff\xfd\x00\x01\x04\x00\x55\x00", ids, 4, out)
    assert out == [False, False, False]


def test_register_codec_and_words() -> None:
    assert Reg.GOAL_POSITION.encode(-1) == b"\xff\xff\xff\xff"
    assert Reg.BUS_WATCHDOG.decode(b"\xff") == -1
    assert Reg.PRESENT_POSITION.decode(b"\x00\x08\x00\x00") == 2048
    with pytest.raises(OverflowError):
        Reg.TORQUE_ENABLE.encode(256)
    assert describe_hardware_error(0x20) == "overload (bit 5)"
    assert describe_hardware_error(0x05) == "input voltage (bit 0), overheating (bit 2)"
    assert describe_status_error(0x84).startswith("alert")
    assert describe_status_error(0x04) == "data range error"


@given(st.lists(st.binary(min_size=3, max_size=3), min_size=1, max_size=6))
def test_fast_sync_valid_odd_data_length(datas: list[bytes]) -> None:
    # odd data length takes the byte-wise path; every block must verify
    ids = tuple(range(1, len(datas) + 1))
    raw = fast_reply([(0, i, d) for i, d in zip(ids, datas, strict=True)])
    out = [False] * len(ids)
    fast_sync_valid(raw, ids, 3, out)
    assert all(out)


@given(st.lists(st.binary(min_size=10, max_size=10), min_size=1, max_size=6),
       st.integers(0, 200))
def test_fast_sync_valid_prefix_on_truncation(datas: list[bytes], cut: int) -> None:
    ids = tuple(range(1, len(datas) + 1))
    raw = fast_reply([(0, i, d) for i, d in zip(ids, datas, strict=True)])
    cut = min(cut, len(raw))
    out = [True] * len(ids)
    fast_sync_valid(raw[:cut], ids, 10, out)
    complete = max(0, (cut - 8) // 14)
    assert out == [i < complete for i in range(len(ids))]


def test_driver_registers_match_the_emulators_control_table() -> None:
    from firmware_protocol.dynamixel import X_SERIES_TABLE
    from firmware_protocol.dynamixel import Reg as TableReg

    for reg in Reg:
        item = X_SERIES_TABLE[TableReg[reg.name]]
        assert (reg.address, reg.size, reg.signed) == (item.address, item.size, item.signed), reg
    for name in ("CURRENT_LIMIT", "POSITION_P_GAIN", "POSITION_D_GAIN", "GOAL_CURRENT"):
        assert name in Reg.__members__
