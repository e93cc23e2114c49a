"""The driver's Protocol 2.0 codec: CRC, framing, instruction and status packets, the
goal Sync Write and the Fast Sync Read reply, with the compiled kernels the cycle uses.

Layouts (ROBOTIS e-manual, protocol 2.0; REFERENCE.md section 1):

- instruction ``FF FF FD 00 | ID | LEN_L LEN_H | INST | params | CRC_L CRC_H``;
- status ``FF FF FD 00 | ID | LEN_L LEN_H | 55 | ERR | params | CRC_L CRC_H``;
- Fast Sync Read reply ``FF FF FD 00 FE LEN_L LEN_H 55`` then per servo
  ``ERR ID data CRC_L CRC_H``, each CRC the running CRC from the header on (the
  last one is the packet's CRC); never stuffed;
- CRC-16 poly 0x8005, init 0, not reflected, over every byte before the CRC.

One CRC implementation: :func:`crc16_kernel`, a table loop compiled by numba, used
inside the kernels and, through :func:`crc16`, for the packets built and parsed in
Python. dynamixel-sdk's ``updateCRC`` is the tests' reference, never called here.
The SDK's own ``txPacket``/``rxPacket`` are not used: they send packets unstuffed,
clear the input buffer, busy-wait on wall time and crash on short replies.

Deliberately separate from ``firmware_protocol/dynamixel.py``, the emulator's codec:
the driver and the emulator it is tested against share no protocol code, so a
misreading of the protocol on one side fails a test instead of cancelling out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from handrig.errors import ProtocolError

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE
MAX_ID = 252
INST_PING = 0x01
INST_READ = 0x02
INST_WRITE = 0x03
INST_REBOOT = 0x08
INST_STATUS = 0x55
INST_SYNC_READ = 0x82
INST_SYNC_WRITE = 0x83
INST_FAST_SYNC_READ = 0x8A
MAX_PACKET_LEN = 1024  # dynamixel-sdk RXPACKET_MAX_LEN
POSITION_TICKS_MAX = 4095  # X-series Goal Position in position control mode
SYNC_WRITE_BODY = 12  # header 4, ID, LEN 2, instruction, address 2, data length 2
FAST_REPLY_HEAD = 8  # header 4, ID, LEN 2, instruction 0x55
FAST_BLOCK_EXTRA = 4  # per servo: ERR, ID, then data, then CRC 2

# fast_sync_whole's refusals (nothing written)
NOT_THIS_REPLY = -3  # wrong length, header or servo order
BAD_CRC = -2  # the CRC over the whole reply fails
ERROR_NUMBER = -1  # some servo answered with an error number


def _crc_table() -> np.ndarray:
    table = np.zeros(256, np.uint16)
    for i in range(256):
        crc = i << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else crc << 1
        table[i] = crc & 0xFFFF
    return table


CRC_TABLE = _crc_table()


# ------------------------------------------------------------------ compiled kernels
@njit(cache=True, nogil=True)
def crc16_kernel(data: Any, start: int, stop: int, crc: int) -> int:  # pragma: no cover
    """The Protocol 2.0 CRC of ``data[start:stop]`` (uint8), continuing from ``crc``."""
    for i in range(start, stop):
        crc = ((crc << 8) ^ CRC_TABLE[((crc >> 8) ^ data[i]) & 0xFF]) & 0xFFFF
    return crc


@njit(cache=True, nogil=True)
def goal_packet(
    goals: Any, low: Any, high: Any, last: Any, hold: Any, ticks_per_deg: Any,
    zero_ticks: Any, goal_out: Any, packet: Any,
) -> int:  # pragma: no cover - compiled
    """Goals clamped into ``goal_out`` and written as Goal Position ticks into the goal
    Sync Write ``packet`` (uint8, whole packet), whose CRC is then recomputed. The
    packet's first ``SYNC_WRITE_BODY`` bytes and each block's ID byte are left alone;
    bytes 1-4 of block ``k`` get servo ``k``'s little-endian position. A non-finite
    goal becomes the last goal sent, or ``hold`` before any. Returns how many goals
    were changed."""
    changed = 0
    for k in range(goals.shape[0]):
        g = goals[k]
        if math.isfinite(g):
            v = min(max(g, low[k]), high[k])
            if v != g:
                changed += 1
        else:
            changed += 1
            v = last[k] if math.isfinite(last[k]) else hold[k]
        goal_out[k] = v
        t = int(np.rint(v * ticks_per_deg[k] + zero_ticks[k]))
        t = min(max(t, 0), POSITION_TICKS_MAX)
        b = SYNC_WRITE_BODY + 5 * k
        packet[b + 1] = t & 0xFF
        packet[b + 2] = (t >> 8) & 0xFF
        packet[b + 3] = 0
        packet[b + 4] = 0
    end = packet.shape[0] - 2
    crc = crc16_kernel(packet, 0, end, 0)
    packet[end] = crc & 0xFF
    packet[end + 1] = crc >> 8
    return changed


@njit(cache=True, nogil=True)
def _le(raw: Any, d: int, size: int) -> int:  # pragma: no cover - compiled
    """The signed little-endian integer of ``size`` bytes at ``raw[d]``."""
    v = 0
    for b in range(size):
        v |= int(raw[d + b]) << (8 * b)
    if v >= 1 << (8 * size - 1):
        v -= 1 << (8 * size)
    return v


@njit(cache=True, nogil=True)
def decode_reading(
    raw: Any, d: int, read_len: int, k: int, scale: Any, latest: Any
) -> None:  # pragma: no cover - compiled
    """The reading at ``raw[d:d + read_len]`` into column ``k`` of ``latest``.

    ``read_len`` 4: Present Position; 10: Present Current (2), Velocity (4),
    Position (4). ``scale`` rows: zero ticks, ticks per joint degree, joint deg/s
    per velocity unit, mA per current unit; ``latest`` rows: position, velocity,
    current (temperature and time are left alone)."""
    if read_len == 10:
        latest[2, k] = _le(raw, d, 2) * scale[3, k]
        latest[1, k] = _le(raw, d + 2, 4) * scale[2, k]
        d += 6
    latest[0, k] = (_le(raw, d, 4) - scale[0, k]) / scale[1, k]


@njit(cache=True, nogil=True)
def _fast_head_ok(raw: Any) -> bool:  # pragma: no cover - compiled
    """Header, ID 0xFE and instruction 0x55 of a Fast Sync Read reply (8+ bytes)."""
    return (raw[0] == 0xFF and raw[1] == 0xFF and raw[2] == 0xFD and raw[3] == 0
            and raw[4] == BROADCAST_ID and raw[7] == INST_STATUS)


@njit(cache=True, nogil=True)
def fast_sync_check(raw: Any, ids: Any, data_len: int, valid: Any) -> int:  # pragma: no cover
    """Check a (possibly truncated) Fast Sync Read reply servo by servo.

    ``valid[i]`` becomes True when block ``i`` is complete, names ``ids[i]`` and
    its running CRC matches (none does under a wrong header). Returns how many
    blocks are complete."""
    n = ids.shape[0]
    for i in range(n):
        valid[i] = False
    if raw.shape[0] < FAST_REPLY_HEAD:
        return 0
    block = data_len + FAST_BLOCK_EXTRA
    complete = min(n, (raw.shape[0] - FAST_REPLY_HEAD) // block)
    if not _fast_head_ok(raw):
        return complete
    crc = crc16_kernel(raw, 0, FAST_REPLY_HEAD, 0)
    for i in range(complete):
        b = FAST_REPLY_HEAD + i * block
        end = b + block
        crc = crc16_kernel(raw, b, end - 2, crc)
        valid[i] = raw[b + 1] == ids[i] and (raw[end - 2] | (raw[end - 1] << 8)) == crc
        crc = crc16_kernel(raw, end - 2, end, crc)
    return complete


@njit(cache=True, nogil=True)
def fast_sync_take(
    raw: Any, read_len: int, order: Any, ids: Any, scale: Any, latest: Any,
    status_err: Any, fresh: Any, valid: Any,
) -> tuple[int, int, int]:  # pragma: no cover - compiled
    """Take what a damaged or partial Fast Sync Read reply holds: for each complete
    block that passes :func:`fast_sync_check`, servo ``order[i]`` gets its ERR byte
    and, unless it is an error number (its data are filler then), its reading and
    ``fresh``. Returns (complete blocks, taken, refused with an error number)."""
    complete = fast_sync_check(raw, ids, read_len, valid)
    taken = refused = 0
    block = read_len + FAST_BLOCK_EXTRA
    for i in range(complete):
        if not valid[i]:
            continue
        b = FAST_REPLY_HEAD + i * block
        k = order[i]
        status_err[k] = raw[b]
        if raw[b] & 0x7F:
            refused += 1
            continue
        decode_reading(raw, b + 2, read_len, k, scale, latest)
        fresh[k] = True
        taken += 1
    return complete, taken, refused


@njit(cache=True, nogil=True)
def fast_sync_whole(
    raw: Any, read_len: int, order: Any, ids: Any, scale: Any, latest: Any,
    status_err: Any, stale_run: Any, fresh: Any, now: float, out: Any, out_u8: Any,
) -> int:  # pragma: no cover - compiled
    """Take a Fast Sync Read reply to a request for every servo, checked and decoded
    in one pass (the cycle's usual case, right after the wait for the reply).

    Block ``i`` must name ``ids[i]`` and carry servo ``order[i]`` (rig index);
    ``scale`` and ``latest`` as in :func:`decode_reading` (``latest`` row 3
    temperature, row 4 time read).

    Returns ``NOT_THIS_REPLY`` or ``BAD_CRC`` (nothing written) when the reply is not
    intact as a whole, ``ERROR_NUMBER`` (nothing written) when a servo reports an
    error number (ERR & 0x7F); otherwise stores every reading, ERR byte and
    ``fresh`` and returns how many servos raise the Alert bit (0x80). When none
    does, the read is complete: the readings' time becomes ``now``, ``stale_run``
    0, and the new state is written out: ``out`` rows position, velocity, current,
    temperature, age (0); ``out_u8`` rows status error, hardware error (0),
    stale (0).
    """
    n = order.shape[0]
    block = read_len + FAST_BLOCK_EXTRA
    total = FAST_REPLY_HEAD + block * n
    length = total - 7
    if (raw.shape[0] != total or not _fast_head_ok(raw) or raw[5] != (length & 0xFF)
            or raw[6] != (length >> 8)):
        return NOT_THIS_REPLY
    for i in range(n):
        if raw[FAST_REPLY_HEAD + 1 + i * block] != ids[i]:
            return NOT_THIS_REPLY
    if crc16_kernel(raw, 0, total - 2, 0) != (raw[total - 2] | (raw[total - 1] << 8)):
        return BAD_CRC
    alerts = 0
    for i in range(n):
        err = raw[FAST_REPLY_HEAD + i * block]
        if err & 0x7F:
            return ERROR_NUMBER
        if err & 0x80:
            alerts += 1
    for i in range(n):
        b = FAST_REPLY_HEAD + i * block
        k = order[i]
        status_err[k] = raw[b]
        fresh[k] = True
        decode_reading(raw, b + 2, read_len, k, scale, latest)
    if alerts == 0:
        for k in range(latest.shape[1]):
            latest[4, k] = now
            stale_run[k] = 0
            for r in range(4):
                out[r, k] = latest[r, k]
            out[4, k] = 0.0
            out_u8[0, k] = status_err[k]
            out_u8[1, k] = 0
            out_u8[2, k] = 0
    return alerts


def warm_up() -> None:
    """Compile (or load from the cache) every kernel with the types the driver uses."""
    f = np.zeros(2)
    goal_packet(f, f - 1.0, f + 1.0, f, f, f + 1.0, f, np.zeros(2),
                np.zeros(SYNC_WRITE_BODY + 12, np.uint8))
    idx = np.zeros(2, np.intp)
    ids = np.frombuffer(bytes(2), np.uint8)  # read-only, as an Order's IDs are
    for read_len in (1, 4, 10):
        reply = np.frombuffer(bytes(8 + 2 * (read_len + 4)), np.uint8)  # read-only, as used
        fast_sync_check(reply, ids, read_len, np.zeros(2, np.bool_))
        fast_sync_take(reply, read_len, idx, ids, np.ones((4, 2)), np.zeros((5, 2)),
                       np.zeros(2, np.uint8), np.zeros(2, np.bool_), np.zeros(2, np.bool_))
        fast_sync_whole(reply, read_len, idx, ids, np.ones((4, 2)), np.zeros((5, 2)),
                        np.zeros(2, np.uint8), np.zeros(2, np.int64), np.zeros(2, np.bool_),
                        0.0, np.zeros((5, 2)), np.zeros((3, 2), np.uint8))
        decode_reading(reply, 0, read_len, 0, np.ones((4, 2)), np.zeros((5, 2)))
    crc16(b"\x00")


# ------------------------------------------------------------------ packets in Python
def crc16(data: bytes | bytearray | memoryview) -> int:
    """The Protocol 2.0 CRC of ``data`` (:func:`crc16_kernel`)."""
    return int(crc16_kernel(np.frombuffer(data, np.uint8), 0, len(data), 0))


def stuff(body: bytes) -> bytes:
    """Byte stuffing: ``FF FF FD`` in the instruction and parameters gets an extra ``FD``."""
    return body.replace(b"\xff\xff\xfd", b"\xff\xff\xfd\xfd")


def unstuff(body: bytes) -> bytes:
    """Undo :func:`stuff`."""
    return body.replace(b"\xff\xff\xfd\xfd", b"\xff\xff\xfd")


def u16(value: int) -> bytes:
    return int(value).to_bytes(2, "little")


def build_instruction(servo_id: int, instruction: int, params: bytes = b"") -> bytes:
    """A complete instruction packet (stuffed, with CRC) for ``servo_id``."""
    if not 0 <= servo_id <= BROADCAST_ID:
        raise ValueError(f"servo id {servo_id} outside 0..{BROADCAST_ID}")
    body = stuff(bytes((instruction,)) + params)
    length = len(body) + 2
    if length + 7 > MAX_PACKET_LEN:
        raise ValueError(f"packet of {length + 7} bytes exceeds {MAX_PACKET_LEN}")
    packet = HEADER + bytes((servo_id, length & 0xFF, length >> 8)) + body
    crc = crc16(packet)
    return packet + bytes((crc & 0xFF, crc >> 8))


def read_request(instruction: int, address: int, data_len: int, ids: bytes) -> bytes:
    """A broadcast Sync Read or Fast Sync Read of ``data_len`` bytes at ``address``."""
    return build_instruction(BROADCAST_ID, instruction, u16(address) + u16(data_len) + ids)


def sync_write_prefix(address: int, data_len: int, n_servos: int) -> bytes:
    """The first ``SYNC_WRITE_BODY`` bytes of a broadcast Sync Write to ``n_servos``."""
    length = 1 + 4 + (1 + data_len) * n_servos + 2
    return HEADER + bytes((BROADCAST_ID, length & 0xFF, length >> 8, INST_SYNC_WRITE)) + u16(
        address) + u16(data_len)


def fast_reply_len(data_len: int, n_servos: int) -> int:
    """Bytes of a Fast Sync Read reply: 8 + (data_len + 4) per servo."""
    return FAST_REPLY_HEAD + (data_len + FAST_BLOCK_EXTRA) * n_servos


def fast_block(raw: bytes, i: int, data_len: int) -> tuple[int, int, bytes]:
    """(ERR, ID, data) of block ``i`` of a Fast Sync Read reply (not checked)."""
    b = FAST_REPLY_HEAD + i * (data_len + FAST_BLOCK_EXTRA)
    return raw[b], raw[b + 1], raw[b + 2 : b + 2 + data_len]


def fast_reply_ids(raw: bytes, data_len: int, n_max: int) -> bytes:
    """The ID bytes of the complete blocks of a Fast Sync Read reply (at most ``n_max``)."""
    block = data_len + FAST_BLOCK_EXTRA
    m = min(n_max, (len(raw) - FAST_REPLY_HEAD) // block)
    return raw[FAST_REPLY_HEAD + 1 : FAST_REPLY_HEAD + max(m, 0) * block : block]


def fast_sync_intact(raw: bytes, ids: bytes, data_len: int, valid: np.ndarray) -> bool:
    """True if ``raw`` is a complete Fast Sync Read reply for ``ids`` (in that order)
    intact in every block (``valid``: scratch of at least ``len(ids)`` bools)."""
    n = len(ids)
    if len(raw) != fast_reply_len(data_len, n) or packet_length(raw) != len(raw):
        return False
    fast_sync_check(np.frombuffer(raw, np.uint8), np.frombuffer(ids, np.uint8), data_len, valid)
    return bool(valid[:n].all())


@dataclass(frozen=True)
class StatusPacket:
    """A status packet: who answered, its ERR byte, the (unstuffed) parameters."""

    servo_id: int
    error: int
    params: bytes


def packet_length(head: bytes | bytearray) -> int:
    """Total length of the packet whose first 7 bytes are ``head`` (header, ID, LEN)."""
    return 7 + (head[5] | head[6] << 8)


def parse_status(raw: bytes | bytearray) -> StatusPacket:
    """Check and decode one framed status packet; ProtocolError names what is wrong."""
    if len(raw) < 11:
        raise ProtocolError(f"status packet of {len(raw)} bytes is shorter than 11")
    if raw[:4] != HEADER:
        raise ProtocolError(f"bad header {bytes(raw[:4]).hex(' ')}")
    total = packet_length(raw)
    if total != len(raw):
        raise ProtocolError(f"LEN says {total} bytes, got {len(raw)}")
    if raw[7] != INST_STATUS:
        raise ProtocolError(f"instruction byte 0x{raw[7]:02x} is not status (0x55)")
    crc = raw[-2] | raw[-1] << 8
    if crc16(memoryview(raw)[:-2]) != crc:
        raise ProtocolError(f"CRC mismatch in status packet from id {raw[4]}")
    return StatusPacket(raw[4], raw[8], unstuff(bytes(raw[9:-2])))
