"""Dynamixel Protocol 2.0 wire format and the X-series control table, as pure code.

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
from enum import Enum, IntEnum, IntFlag

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


# ----------------------------------------------------------- X-series control table


class Area(Enum):
    EEPROM = "EEPROM"
    RAM = "RAM"


class Access(Enum):
    R = "R"
    RW = "RW"


@dataclass(frozen=True)
class Item:
    """One control-table item: address, size in bytes, memory area, access, value range."""

    address: int
    size: int
    area: Area
    access: Access
    signed: bool = False
    min_value: int | None = None
    max_value: int | None = None

    def encode(self, value: int) -> bytes:
        return int(value).to_bytes(self.size, "little", signed=self.signed)

    def decode(self, data: bytes | bytearray) -> int:
        return int.from_bytes(data, "little", signed=self.signed)


class Reg(IntEnum):
    """X-series (XL330 / XC330 / XM430) control-table items; the value is the address."""

    MODEL_NUMBER = 0
    MODEL_INFORMATION = 2
    FIRMWARE_VERSION = 6
    ID = 7
    BAUD_RATE = 8
    RETURN_DELAY_TIME = 9
    DRIVE_MODE = 10
    OPERATING_MODE = 11
    SECONDARY_ID = 12
    PROTOCOL_TYPE = 13
    HOMING_OFFSET = 20
    MOVING_THRESHOLD = 24
    TEMPERATURE_LIMIT = 31
    MAX_VOLTAGE_LIMIT = 32
    MIN_VOLTAGE_LIMIT = 34
    PWM_LIMIT = 36
    CURRENT_LIMIT = 38
    VELOCITY_LIMIT = 44
    MAX_POSITION_LIMIT = 48
    MIN_POSITION_LIMIT = 52
    STARTUP_CONFIGURATION = 60
    SHUTDOWN = 63
    TORQUE_ENABLE = 64
    LED = 65
    STATUS_RETURN_LEVEL = 68
    REGISTERED_INSTRUCTION = 69
    HARDWARE_ERROR_STATUS = 70
    VELOCITY_I_GAIN = 76
    VELOCITY_P_GAIN = 78
    POSITION_D_GAIN = 80
    POSITION_I_GAIN = 82
    POSITION_P_GAIN = 84
    FEEDFORWARD_2ND_GAIN = 88
    FEEDFORWARD_1ST_GAIN = 90
    BUS_WATCHDOG = 98
    GOAL_PWM = 100
    GOAL_CURRENT = 102
    GOAL_VELOCITY = 104
    PROFILE_ACCELERATION = 108
    PROFILE_VELOCITY = 112
    GOAL_POSITION = 116
    REALTIME_TICK = 120
    MOVING = 122
    MOVING_STATUS = 123
    PRESENT_PWM = 124
    PRESENT_CURRENT = 126
    PRESENT_VELOCITY = 128
    PRESENT_POSITION = 132
    VELOCITY_TRAJECTORY = 136
    POSITION_TRAJECTORY = 140
    PRESENT_INPUT_VOLTAGE = 144
    PRESENT_TEMPERATURE = 146


_E, _R = Area.EEPROM, Area.RAM
_RO, _RW = Access.R, Access.RW

# Sizes, areas, access and ranges from the XL330-M288 control table (e-manual);
# XC330 and XM430 share the layout. Ranges that depend on a limit register
# (goal position, goal current, ...) are checked by the servo, not here.
X_SERIES_TABLE: dict[Reg, Item] = {
    Reg.MODEL_NUMBER: Item(0, 2, _E, _RO),
    Reg.MODEL_INFORMATION: Item(2, 4, _E, _RO),
    Reg.FIRMWARE_VERSION: Item(6, 1, _E, _RO),
    Reg.ID: Item(7, 1, _E, _RW, min_value=0, max_value=252),
    Reg.BAUD_RATE: Item(8, 1, _E, _RW, min_value=0, max_value=6),
    Reg.RETURN_DELAY_TIME: Item(9, 1, _E, _RW, min_value=0, max_value=254),
    Reg.DRIVE_MODE: Item(10, 1, _E, _RW, min_value=0, max_value=13),
    Reg.OPERATING_MODE: Item(11, 1, _E, _RW, min_value=0, max_value=16),
    Reg.SECONDARY_ID: Item(12, 1, _E, _RW, min_value=0, max_value=255),
    Reg.PROTOCOL_TYPE: Item(13, 1, _E, _RW, min_value=1, max_value=22),
    Reg.HOMING_OFFSET: Item(20, 4, _E, _RW, True, -1_044_479, 1_044_479),
    Reg.MOVING_THRESHOLD: Item(24, 4, _E, _RW, False, 0, 1023),
    Reg.TEMPERATURE_LIMIT: Item(31, 1, _E, _RW, min_value=0, max_value=100),
    Reg.MAX_VOLTAGE_LIMIT: Item(32, 2, _E, _RW, min_value=31, max_value=70),
    Reg.MIN_VOLTAGE_LIMIT: Item(34, 2, _E, _RW, min_value=31, max_value=70),
    Reg.PWM_LIMIT: Item(36, 2, _E, _RW, min_value=0, max_value=885),
    Reg.CURRENT_LIMIT: Item(38, 2, _E, _RW, min_value=0, max_value=1750),
    Reg.VELOCITY_LIMIT: Item(44, 4, _E, _RW, min_value=0, max_value=2047),
    Reg.MAX_POSITION_LIMIT: Item(48, 4, _E, _RW, min_value=0, max_value=4095),
    Reg.MIN_POSITION_LIMIT: Item(52, 4, _E, _RW, min_value=0, max_value=4095),
    Reg.STARTUP_CONFIGURATION: Item(60, 1, _E, _RW, min_value=0, max_value=3),
    Reg.SHUTDOWN: Item(63, 1, _E, _RW, min_value=0, max_value=255),
    Reg.TORQUE_ENABLE: Item(64, 1, _R, _RW, min_value=0, max_value=1),
    Reg.LED: Item(65, 1, _R, _RW, min_value=0, max_value=1),
    Reg.STATUS_RETURN_LEVEL: Item(68, 1, _R, _RW, min_value=0, max_value=2),
    Reg.REGISTERED_INSTRUCTION: Item(69, 1, _R, _RO),
    Reg.HARDWARE_ERROR_STATUS: Item(70, 1, _R, _RO),
    Reg.VELOCITY_I_GAIN: Item(76, 2, _R, _RW, min_value=0, max_value=16383),
    Reg.VELOCITY_P_GAIN: Item(78, 2, _R, _RW, min_value=0, max_value=16383),
    Reg.POSITION_D_GAIN: Item(80, 2, _R, _RW, min_value=0, max_value=16383),
    Reg.POSITION_I_GAIN: Item(82, 2, _R, _RW, min_value=0, max_value=16383),
    Reg.POSITION_P_GAIN: Item(84, 2, _R, _RW, min_value=0, max_value=16383),
    Reg.FEEDFORWARD_2ND_GAIN: Item(88, 2, _R, _RW, min_value=0, max_value=16383),
    Reg.FEEDFORWARD_1ST_GAIN: Item(90, 2, _R, _RW, min_value=0, max_value=16383),
    Reg.BUS_WATCHDOG: Item(98, 1, _R, _RW, True, 0, 127),  # the servo sets -1 on a trip
    Reg.GOAL_PWM: Item(100, 2, _R, _RW, True, -885, 885),
    Reg.GOAL_CURRENT: Item(102, 2, _R, _RW, True, -1750, 1750),
    Reg.GOAL_VELOCITY: Item(104, 4, _R, _RW, True, -2047, 2047),
    Reg.PROFILE_ACCELERATION: Item(108, 4, _R, _RW, False, 0, 32767),
    Reg.PROFILE_VELOCITY: Item(112, 4, _R, _RW, False, 0, 32767),
    Reg.GOAL_POSITION: Item(116, 4, _R, _RW, True, -1_048_575, 1_048_575),
    Reg.REALTIME_TICK: Item(120, 2, _R, _RO),
    Reg.MOVING: Item(122, 1, _R, _RO),
    Reg.MOVING_STATUS: Item(123, 1, _R, _RO),
    Reg.PRESENT_PWM: Item(124, 2, _R, _RO, True),
    Reg.PRESENT_CURRENT: Item(126, 2, _R, _RO, True),
    Reg.PRESENT_VELOCITY: Item(128, 4, _R, _RO, True),
    Reg.PRESENT_POSITION: Item(132, 4, _R, _RO, True),
    Reg.VELOCITY_TRAJECTORY: Item(136, 4, _R, _RO, True),
    Reg.POSITION_TRAJECTORY: Item(140, 4, _R, _RO, True),
    Reg.PRESENT_INPUT_VOLTAGE: Item(144, 2, _R, _RO),
    Reg.PRESENT_TEMPERATURE: Item(146, 1, _R, _RO),
}
# Control-table memory modelled, in bytes (items end at 147; indirect data not modelled).
CONTROL_TABLE_BYTES = 148
EEPROM_END = 64


@dataclass(frozen=True)
class ModelInfo:
    """A servo model: model number, firmware, defaults that differ between models."""

    name: str
    model_number: int
    firmware_version: int
    stall_torque_nm: float  # at the nominal voltage
    stall_current_a: float
    no_load_speed_rpm: float
    current_limit: int  # Current Limit (38) default, units of 1 mA (XL330) / 2.69 mA (XM430)
    current_unit_ma: float
    nominal_voltage_dv: int  # Present Input Voltage, units of 0.1 V
    position_p_gain: int
    position_d_gain: int


# Datasheet figures (ROBOTIS e-manual): XL330-M288 0.52 Nm / 1.47 A / 103 rpm at 5 V;
# XC330-T288 0.92 Nm / 0.8 A / 67 rpm at 11.1 V; XM430-W350 4.1 Nm / 2.3 A / 46 rpm at 12 V;
# XC330-M288 (the LEAP hand's servo) 0.93 Nm / 1.80 A / 81 rpm at 5 V, model number 1240,
# Current Limit 2352 x 1 mA, Position P 1100 / D 500 by default.
MODELS: dict[str, ModelInfo] = {
    "XL330-M288": ModelInfo("XL330-M288", 1200, 46, 0.52, 1.47, 103.0, 1750, 1.0, 50, 400, 0),
    "XC330-T288": ModelInfo("XC330-T288", 1220, 46, 0.92, 0.8, 67.0, 910, 1.0, 120, 400, 0),
    "XC330-M288": ModelInfo("XC330-M288", 1240, 46, 0.93, 1.80, 81.0, 2352, 1.0, 50, 1100, 500),
    "XM430-W350": ModelInfo("XM430-W350", 1020, 46, 4.1, 2.3, 46.0, 1193, 2.69, 120, 800, 0),
}
MODEL_BY_NUMBER: dict[int, ModelInfo] = {m.model_number: m for m in MODELS.values()}

# Baud Rate (8) index -> bits per second.
BAUD_BY_INDEX: dict[int, int] = {
    0: 9600, 1: 57600, 2: 115200, 3: 1_000_000, 4: 2_000_000, 5: 3_000_000, 6: 4_000_000,
}
INDEX_BY_BAUD: dict[int, int] = {v: k for k, v in BAUD_BY_INDEX.items()}
# Units: Present Velocity 0.229 rpm; Return Delay Time 2 us; Bus Watchdog 20 ms.
VELOCITY_UNIT_RPM = 0.229
RETURN_DELAY_UNIT_S = 2e-6
BUS_WATCHDOG_UNIT_S = 0.020
TICKS_PER_TURN = 4096


def items_covering(address: int, length: int) -> list[Item] | None:
    """The items exactly covering ``[address, address + length)``, or ``None`` when the
    range cuts an item or touches an undefined address."""
    out: list[Item] = []
    pos = address
    end = address + length
    while pos < end:
        item = ITEM_AT.get(pos)
        if item is None or pos + item.size > end:
            return None
        out.append(item)
        pos += item.size
    return out


ITEM_AT: dict[int, Item] = {item.address: item for item in X_SERIES_TABLE.values()}
