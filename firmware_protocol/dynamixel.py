"""Dynamixel Protocol 2.0 wire format, as pure code (control tables: ``dxl_tables``).

Facts from the ROBOTIS e-manual (``protocol2``, XL330-M288 / XC330-T288 /
XM430-W350 control tables), collected in REFERENCE.md sections 1-2:

- Instruction: ``FF FF FD 00 | ID | LEN_L LEN_H | INST | params | CRC_L CRC_H``,
  LEN = len(params) + 3.
- Status: ``FF FF FD 00 | ID | LEN_L LEN_H | 55 | ERR | params | CRC_L CRC_H``,
  LEN = len(params) + 4.
- CRC-16/BUYPASS (polynomial 0x8005, initial 0, not reflected) over every byte
  from the first ``FF`` to the byte before the CRC.
- Byte stuffing: ``FF FF FD`` inside INST..params gets an extra ``FD``; the CRC
  covers the stuffed packet.
- Fast Sync Read / Fast Bulk Read reply: one packet from ID 0xFE whose body is,
  per servo, ``ERR ID data CRC_L CRC_H``; each CRC is the running CRC over all
  bytes before it; the last one is the packet CRC; never stuffed.

No I/O, no clock, imports neither ``handrig`` nor ``sim``.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from enum import IntEnum, IntFlag

# The control tables live in dxl_tables; re-exported here for the codec's users.
from firmware_protocol.dxl_tables import (
    BAUD_BY_INDEX,
    BUS_WATCHDOG_UNIT_S,
    CONTROL_TABLE_BYTES,
    EEPROM_END,
    INDEX_BY_BAUD,
    ITEM_AT,
    MODEL_BY_NUMBER,
    MODELS,
    RETURN_DELAY_UNIT_S,
    TICKS_PER_TURN,
    VELOCITY_UNIT_RPM,
    X_SERIES_TABLE,
    Access,
    Area,
    Item,
    ModelInfo,
    Reg,
    items_covering,
)

__all__ = [
    "BAUD_BY_INDEX",
    "BROADCAST_ID",
    "BUS_WATCHDOG_UNIT_S",
    "CONTROL_TABLE_BYTES",
    "CRC_TABLE",
    "EEPROM_END",
    "ERROR_ALERT",
    "HEADER",
    "HEADER_LEN",
    "INDEX_BY_BAUD",
    "ITEM_AT",
    "MAX_ID",
    "MAX_PACKET_LEN",
    "MODELS",
    "MODEL_BY_NUMBER",
    "PREFIX_LEN",
    "RETURN_DELAY_UNIT_S",
    "STATUS_INSTRUCTION",
    "TICKS_PER_TURN",
    "VELOCITY_UNIT_RPM",
    "X_SERIES_TABLE",
    "Access",
    "Area",
    "ErrorCode",
    "HardwareError",
    "Instruction",
    "InstructionPacket",
    "Item",
    "ModelInfo",
    "PacketError",
    "Reg",
    "StatusPacket",
    "build_fast_read_reply",
    "build_instruction",
    "build_status",
    "bulk_read_params",
    "bulk_write_params",
    "crc16",
    "find_frame",
    "items_covering",
    "parse_fast_read_reply",
    "parse_instruction",
    "parse_status",
    "read_params",
    "split_bulk_read",
    "split_bulk_write",
    "split_sync_read",
    "split_sync_write",
    "stuff",
    "sync_read_params",
    "sync_write_params",
    "unstuff",
    "with_crc",
    "write_params",
]

HEADER = b"\xff\xff\xfd\x00"
HEADER_LEN = 4
STATUS_INSTRUCTION = 0x55
BROADCAST_ID = 0xFE
MAX_ID = 252
# Bytes before the instruction byte: header(4) + ID(1) + LEN(2).
PREFIX_LEN = 7
# The SDK's RXPACKET_MAX_LEN / TXPACKET_MAX_LEN (dynamixel-sdk 4.1.0 robotis_def.py).
MAX_PACKET_LEN = 1024
ERROR_ALERT = 0x80
_STUFF_FROM = b"\xff\xff\xfd"
_STUFF_TO = b"\xff\xff\xfd\xfd"


class Instruction(IntEnum):
    """Instruction byte values (e-manual protocol2, 'Instruction')."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    STATUS = 0x55
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    FAST_SYNC_READ = 0x8A
    BULK_READ = 0x92
    BULK_WRITE = 0x93
    FAST_BULK_READ = 0x9A


class ErrorCode(IntEnum):
    """Bits 0-6 of a status packet's ERR byte (a number, not flags)."""

    NONE = 0
    RESULT_FAIL = 1
    INSTRUCTION = 2
    CRC = 3
    DATA_RANGE = 4
    DATA_LENGTH = 5
    DATA_LIMIT = 6
    ACCESS = 7


class HardwareError(IntFlag):
    """Hardware Error Status (address 70) bits."""

    INPUT_VOLTAGE = 1 << 0
    OVERHEATING = 1 << 2
    MOTOR_ENCODER = 1 << 3
    ELECTRICAL_SHOCK = 1 << 4
    OVERLOAD = 1 << 5


class PacketError(ValueError):
    """Bytes do not form a valid packet. ``kind`` is one of 'header', 'length', 'crc', 'format'."""

    def __init__(self, kind: str, message: str) -> None:
        self.kind = kind
        super().__init__(message)


# ---------------------------------------------------------------------------- CRC


def _make_crc_table() -> tuple[int, ...]:
    table = []
    for i in range(256):
        crc = i << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


CRC_TABLE: tuple[int, ...] = _make_crc_table()
_crc_words: list[int] = []


def _word_table() -> list[int]:
    """CRC after feeding the 16-bit word ``v`` into a zero register, for every ``v``:
    a 16-bit CRC register is fully replaced by two bytes, so crc' = T16[crc ^ word]."""
    if not _crc_words:
        table = CRC_TABLE
        out = [0] * 65536
        for hi in range(256):
            c1 = table[hi]
            c1_hi, c1_lo = c1 >> 8, (c1 << 8) & 0xFF00
            base = hi << 8
            for lo in range(256):
                out[base | lo] = c1_lo ^ table[c1_hi ^ lo]
        _crc_words.extend(out)
    return _crc_words


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-16/BUYPASS of ``data``, continuing from ``crc`` (0 to start).

    Two bytes per step through a 65536-entry table (built on first use, ~20 ms)."""
    words = _word_table()
    n = len(data)
    if n >= 2:
        for w in struct.unpack_from(f">{n >> 1}H", data):
            crc = words[crc ^ w]
    if n & 1:
        crc = ((crc << 8) & 0xFF00) ^ CRC_TABLE[(crc >> 8) ^ data[n - 1]]
    return crc


def with_crc(body: bytes | bytearray) -> bytes:
    """``body`` followed by its CRC, little-endian."""
    return bytes(body) + crc16(body).to_bytes(2, "little")


# ------------------------------------------------------------------------ stuffing


def stuff(payload: bytes | bytearray) -> bytes:
    """Byte-stuff an INST..params region: every ``FF FF FD`` gets an extra ``FD``."""
    return bytes(payload).replace(_STUFF_FROM, _STUFF_TO)


def unstuff(payload: bytes | bytearray) -> bytes:
    """Undo :func:`stuff`: ``FF FF FD FD`` becomes ``FF FF FD``."""
    return bytes(payload).replace(_STUFF_TO, _STUFF_FROM)


# ------------------------------------------------------------------------- packets


@dataclass(frozen=True)
class InstructionPacket:
    """An instruction from the master; ``params`` unstuffed."""

    id: int
    instruction: int
    params: bytes = b""


@dataclass(frozen=True)
class StatusPacket:
    """A servo's reply; ``error`` is the whole ERR byte (alert bit included)."""

    id: int
    error: int
    params: bytes = b""

    @property
    def error_code(self) -> int:
        return self.error & 0x7F

    @property
    def alert(self) -> bool:
        return bool(self.error & ERROR_ALERT)


def _frame(servo_id: int, region: bytes, do_stuff: bool) -> bytes:
    if do_stuff:
        region = stuff(region)
    length = len(region) + 2
    return with_crc(HEADER + bytes((servo_id,)) + length.to_bytes(2, "little") + region)


def build_instruction(
    servo_id: int, instruction: int, params: bytes | bytearray = b"", *, do_stuff: bool = True
) -> bytes:
    """An instruction packet with CRC (stuffed unless ``do_stuff`` is False, as the SDK sends)."""
    _check_id(servo_id, allow_broadcast=True)
    return _frame(servo_id, bytes((instruction,)) + bytes(params), do_stuff)


def build_status(servo_id: int, error: int = 0, params: bytes | bytearray = b"") -> bytes:
    """A status packet with CRC, byte-stuffed."""
    _check_id(servo_id, allow_broadcast=False)
    return _frame(servo_id, bytes((STATUS_INSTRUCTION, error & 0xFF)) + bytes(params), True)


def _check_id(servo_id: int, *, allow_broadcast: bool) -> None:
    if not (0 <= servo_id <= MAX_ID or (allow_broadcast and servo_id == BROADCAST_ID)):
        raise ValueError(f"servo ID {servo_id} out of range 0..{MAX_ID}")


def find_frame(buf: bytes | bytearray, start: int = 0) -> tuple[int, int] | None:
    """Locate the next complete frame in ``buf`` at or after ``start``, framing by LEN.

    Returns ``(begin, end)`` of the frame, or ``None`` if no complete frame is
    there yet (``buf.find(HEADER, start)`` then tells where a partial one begins).
    The CRC is not checked here. A header whose LEN is below 3 or above
    ``MAX_PACKET_LEN`` is skipped as noise.
    """
    while True:
        begin = buf.find(HEADER, start)
        if begin < 0 or len(buf) - begin < PREFIX_LEN:
            return None
        length = buf[begin + 5] | (buf[begin + 6] << 8)
        if length < 3 or length > MAX_PACKET_LEN:
            start = begin + 1
            continue
        end = begin + PREFIX_LEN + length
        if end > len(buf):
            return None
        return begin, end


def _check_frame(frame: bytes | bytearray) -> int:
    if len(frame) < PREFIX_LEN + 3 or frame[:HEADER_LEN] != HEADER:
        raise PacketError("header", f"not a packet: {bytes(frame[:8]).hex(' ')}")
    length = frame[5] | (frame[6] << 8)
    if len(frame) != PREFIX_LEN + length:
        raise PacketError(
            "length", f"LEN says {length} bytes after it, frame has {len(frame) - PREFIX_LEN}"
        )
    want = crc16(memoryview(frame)[:-2])
    got = frame[-2] | (frame[-1] << 8)
    if want != got:
        raise PacketError("crc", f"CRC {got:04X} on the wire, {want:04X} computed")
    return length


def parse_instruction(frame: bytes | bytearray) -> InstructionPacket:
    """Check CRC and LEN of one framed instruction packet and unstuff it."""
    _check_frame(frame)
    region = unstuff(frame[PREFIX_LEN:-2])
    return InstructionPacket(frame[4], region[0], region[1:])


def parse_status(frame: bytes | bytearray) -> StatusPacket:
    """Check CRC and LEN of one framed status packet and unstuff it."""
    length = _check_frame(frame)
    if length < 4 or frame[PREFIX_LEN] != STATUS_INSTRUCTION:
        raise PacketError("format", f"not a status packet (instruction {frame[PREFIX_LEN]:#04x})")
    region = unstuff(frame[PREFIX_LEN:-2])
    return StatusPacket(frame[4], region[1], region[2:])


# ------------------------------------------------- instruction parameter layouts


def read_params(address: int, length: int) -> bytes:
    """Parameters of READ: address and length, both LE16."""
    return struct.pack("<HH", address, length)


def write_params(address: int, data: bytes | bytearray) -> bytes:
    return struct.pack("<H", address) + bytes(data)


def sync_read_params(address: int, length: int, ids: Iterable[int]) -> bytes:
    """Parameters of SYNC READ and FAST SYNC READ."""
    return struct.pack("<HH", address, length) + bytes(ids)


def sync_write_params(address: int, length: int, items: Iterable[tuple[int, bytes]]) -> bytes:
    """Parameters of SYNC WRITE: address, length, then ``ID data`` per servo."""
    out = bytearray(struct.pack("<HH", address, length))
    for servo_id, data in items:
        if len(data) != length:
            raise ValueError(f"servo {servo_id}: {len(data)} data bytes, sync write says {length}")
        out.append(servo_id)
        out += data
    return bytes(out)


def bulk_read_params(items: Iterable[tuple[int, int, int]]) -> bytes:
    """Parameters of BULK READ / FAST BULK READ: ``ID addr16 len16`` per servo."""
    return b"".join(struct.pack("<BHH", i, a, n) for i, a, n in items)


def bulk_write_params(items: Iterable[tuple[int, int, bytes]]) -> bytes:
    """Parameters of BULK WRITE: ``ID addr16 len16 data`` per servo."""
    return b"".join(struct.pack("<BHH", i, a, len(d)) + bytes(d) for i, a, d in items)


def split_sync_read(params: bytes) -> tuple[int, int, bytes]:
    """(address, length, ids) of SYNC READ / FAST SYNC READ parameters."""
    if len(params) < 5:
        raise PacketError("format", f"sync read needs 5+ parameter bytes, got {len(params)}")
    address, length = struct.unpack_from("<HH", params)
    return address, length, params[4:]


def split_sync_write(params: bytes) -> tuple[int, int, list[tuple[int, bytes]]]:
    """(address, length, [(id, data)]) of SYNC WRITE parameters."""
    if len(params) < 4:
        raise PacketError("format", f"sync write needs 4+ parameter bytes, got {len(params)}")
    address, length = struct.unpack_from("<HH", params)
    step = length + 1
    body = params[4:]
    if length == 0 or len(body) % step:
        raise PacketError(
            "format", f"sync write body of {len(body)} bytes is not N x (1 + {length})"
        )
    return address, length, [(body[k], body[k + 1 : k + step]) for k in range(0, len(body), step)]


def split_bulk_read(params: bytes) -> list[tuple[int, int, int]]:
    """[(id, address, length)] of BULK READ / FAST BULK READ parameters."""
    if not params or len(params) % 5:
        raise PacketError("format", f"bulk read body of {len(params)} bytes is not N x 5")
    return [struct.unpack_from("<BHH", params, k) for k in range(0, len(params), 5)]


def split_bulk_write(params: bytes) -> list[tuple[int, int, bytes]]:
    """[(id, address, data)] of BULK WRITE parameters."""
    out: list[tuple[int, int, bytes]] = []
    k = 0
    while k < len(params):
        if len(params) - k < 5:
            raise PacketError("format", f"bulk write entry at byte {k} is cut short")
        servo_id, address, length = struct.unpack_from("<BHH", params, k)
        k += 5
        if length == 0 or len(params) - k < length:
            raise PacketError("format", f"bulk write entry for servo {servo_id} is cut short")
        out.append((servo_id, address, params[k : k + length]))
        k += length
    return out


# --------------------------------------------------- fast sync / fast bulk read


def build_fast_read_reply(chunks: Sequence[tuple[int, int, bytes]]) -> bytes:
    """The combined reply to FAST SYNC READ / FAST BULK READ.

    ``chunks`` are ``(id, error, data)`` in the order requested. LEN = 1 +
    sum(len(data) + 4); each per-servo CRC is the running CRC from the header.
    """
    length = 1 + sum(len(d) + 4 for _, _, d in chunks)
    out = bytearray(HEADER)
    out.append(BROADCAST_ID)
    out += length.to_bytes(2, "little")
    out.append(STATUS_INSTRUCTION)
    crc = 0
    start = 0
    for servo_id, error, data in chunks:
        out.append(error & 0xFF)
        out.append(servo_id)
        out += data
        # running CRC: from the end of the previous CRC (or the header) to here
        crc = crc16(memoryview(out)[start:], crc)
        start = len(out)
        out += crc.to_bytes(2, "little")
    return bytes(out)


def parse_fast_read_reply(
    frame: bytes | bytearray, lengths: Sequence[int]
) -> list[StatusPacket]:
    """Split a fast read reply into per-servo results, checking every running CRC.

    ``lengths`` are the data lengths requested, in order (all equal for a sync read).
    """
    length = _check_frame(frame)
    if frame[4] != BROADCAST_ID or frame[PREFIX_LEN] != STATUS_INSTRUCTION:
        raise PacketError("format", "a fast read reply comes from ID 0xFE with instruction 0x55")
    if length != 1 + sum(n + 4 for n in lengths):
        raise PacketError("length", f"LEN {length} does not fit data lengths {list(lengths)}")
    out: list[StatusPacket] = []
    pos = PREFIX_LEN + 1
    for n in lengths:
        end = pos + 2 + n
        want = crc16(memoryview(frame)[:end])
        got = frame[end] | (frame[end + 1] << 8)
        if want != got:
            raise PacketError("crc", f"running CRC of servo {frame[pos + 1]} is {got:04X}, "
                              f"want {want:04X}")
        out.append(StatusPacket(frame[pos + 1], frame[pos], bytes(frame[pos + 2 : end])))
        pos = end + 2
    return out
