"""Protocol 2.0 packets: CRC, instruction packets, status packets, Fast Sync Read replies.

The CRC table is the one in dynamixel-sdk (``Protocol2PacketHandler.updateCRC``),
taken from the SDK at import so both sides of the wire agree by construction. The
SDK's own ``txPacket``/``rxPacket`` are not used: they send packets unstuffed,
clear the input buffer, busy-wait on wall time and crash on short replies
(Dynamixel SDK notes); here packets are plain ``bytes`` and every check is a
:class:`~handrig.errors.ProtocolError` or a returned flag.

Deliberately separate from ``firmware_protocol/dynamixel.py``, the emulator's codec:
the driver and the emulator it is tested against share no protocol code (this side
takes its CRC from the SDK, that side builds its own from the e-manual), so a
misreading of the protocol on one side fails a test instead of cancelling out.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

from dynamixel_sdk import robotis_def as sdk_def
from dynamixel_sdk.protocol2_packet_handler import Protocol2PacketHandler

from handrig.errors import ProtocolError

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID: int = sdk_def.BROADCAST_ID
MAX_ID: int = sdk_def.MAX_ID
INST_PING: int = sdk_def.INST_PING
INST_READ: int = sdk_def.INST_READ
INST_WRITE: int = sdk_def.INST_WRITE
INST_REBOOT: int = sdk_def.INST_REBOOT
INST_STATUS: int = sdk_def.INST_STATUS
INST_SYNC_READ: int = sdk_def.INST_SYNC_READ
INST_SYNC_WRITE: int = sdk_def.INST_SYNC_WRITE
INST_FAST_SYNC_READ: int = sdk_def.INST_FAST_SYNC_READ
MAX_PACKET_LEN = 1024  # dynamixel-sdk RXPACKET_MAX_LEN

_SDK_HANDLER = Protocol2PacketHandler()
# updateCRC(0, [b], 1) is exactly the SDK's table entry for byte b.
CRC_TABLE: tuple[int, ...] = tuple(_SDK_HANDLER.updateCRC(0, [b], 1) for b in range(256))


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-16 (poly 0x8005, init 0, not reflected) of ``data``, continuing from ``crc``."""
    table = CRC_TABLE
    view = memoryview(data)
    even = len(view) & ~1
    if even and _LITTLE_ENDIAN:
        crc = _crc16_words(view[:even], crc)
        view = view[even:]
    for b in view:
        crc = ((crc & 0xFF) << 8) ^ table[(crc >> 8) ^ b]
    return crc


def _swap(v: int) -> int:
    return ((v & 0xFF) << 8) | (v >> 8)


_LITTLE_ENDIAN = sys.byteorder == "little"
_WORD_TABLE: list[int] = []


def _word_table() -> list[int]:
    """CRC step for 16 bits at once, indexed and valued in byte-swapped form.

    Holding the CRC byte-swapped lets a little-endian ``memoryview.cast("H")``
    word feed it directly: ``swap(crc') = T[swap(crc) ^ word]``. Built once from
    :data:`CRC_TABLE` (65536 entries, about 40 ms).
    """
    if not _WORD_TABLE:
        table = CRC_TABLE
        out = [0] * 65536
        for x in range(65536):
            c = table[x >> 8]
            c = ((c & 0xFF) << 8) ^ table[(c >> 8) ^ (x & 0xFF)]
            out[_swap(x)] = _swap(c)
        _WORD_TABLE[:] = out
    return _WORD_TABLE


def _crc16_words(view: memoryview, crc: int) -> int:
    """CRC over an even number of bytes, two at a time (little-endian hosts only)."""
    table = _word_table()
    crc = _swap(crc)
    for w in view.cast("H"):
        crc = table[crc ^ w]
    return _swap(crc)


def stuff(body: bytes) -> bytes:
    """Byte stuffing: ``FF FF FD`` in the instruction and parameters gets an extra ``FD``."""
    return body.replace(b"\xff\xff\xfd", b"\xff\xff\xfd\xfd")


def unstuff(body: bytes) -> bytes:
    """Undo :func:`stuff`."""
    return body.replace(b"\xff\xff\xfd\xfd", b"\xff\xff\xfd")


def build_instruction(servo_id: int, instruction: int, params: bytes = b"") -> bytes:
    """A complete instruction packet (stuffed, with CRC) for ``servo_id``."""
    if not 0 <= servo_id <= BROADCAST_ID:
        raise ValueError(f"servo id {servo_id} outside 0..{BROADCAST_ID}")
    body = stuff(bytes((instruction,)) + params)
    length = len(body) + 2
    if length + 7 > MAX_PACKET_LEN:
        raise ValueError(f"packet of {length + 7} bytes exceeds {MAX_PACKET_LEN}")
    head = HEADER + bytes((servo_id, length & 0xFF, length >> 8))
    crc = crc16(body, crc16(head))
    return head + body + bytes((crc & 0xFF, crc >> 8))


def u16(value: int) -> bytes:
    return int(value).to_bytes(2, "little")


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


def fast_sync_valid(
    raw: bytes | bytearray, ids: tuple[int, ...], data_len: int, out: list[bool]
) -> None:
    """Check a (possibly truncated) Fast Sync Read reply servo by servo.

    The reply is ``FF FF FD 00 FE LEN_L LEN_H 55`` then per servo
    ``[ERR, ID, data(data_len), CRC_L, CRC_H]`` where each CRC is the running CRC
    from the header on (REFERENCE.md section 1). ``out[i]`` becomes True when block
    ``i`` is complete, names ``ids[i]`` and its running CRC matches. The header is
    checked too; a wrong header leaves every entry False.
    """
    n = len(ids)
    for i in range(n):
        out[i] = False
    if len(raw) < 8 or raw[:5] != b"\xff\xff\xfd\x00\xfe" or raw[7] != INST_STATUS:
        return
    block = data_len + 4
    complete = min(n, (len(raw) - 8) // block)
    if block % 2 == 0 and _LITTLE_ENDIAN:
        # two bytes at a time, CRC held byte-swapped (see _word_table)
        table = _word_table()
        words = memoryview(raw)[: 8 + complete * block].cast("H")
        crc = 0
        for w in words[:4]:
            crc = table[crc ^ w]
        half = block // 2
        pos = 4
        for i in range(complete):
            end = pos + half - 1
            for w in words[pos:end]:
                crc = table[crc ^ w]
            sent = words[end]
            out[i] = crc == _swap(sent) and raw[8 + i * block + 1] == ids[i]
            crc = table[crc ^ sent]
            pos = end + 1
        return
    crc = crc16(raw[:8])
    pos = 8
    for i in range(complete):
        end = pos + block
        crc = crc16(raw[pos : end - 2], crc)
        out[i] = raw[pos + 1] == ids[i] and (raw[end - 2] | raw[end - 1] << 8) == crc
        crc = crc16(raw[end - 2 : end], crc)
        pos = end


def fast_sync_intact(raw: bytes, ids: bytes, data_len: int) -> bool:
    """True if a complete Fast Sync Read reply for ``ids`` is intact as a whole.

    Checks the header, LEN, that block ``i`` names ``ids[i]`` and the final CRC,
    which covers every byte before it (the per-servo CRCs included): the cheap
    test for the usual case; :func:`fast_sync_valid` finds the good servos of a
    damaged reply.
    """
    n = len(ids)
    block = data_len + 4
    total = 8 + block * n
    length = total - 7
    if (
        len(raw) != total
        or raw[:5] != b"\xff\xff\xfd\x00\xfe"
        or raw[5] != length & 0xFF
        or raw[6] != length >> 8
        or raw[7] != INST_STATUS
        or raw[9:total:block] != ids
    ):
        return False
    return crc16(memoryview(raw)[:-2]) == raw[-2] | raw[-1] << 8


def warm_up() -> None:
    """Build the CRC word table now rather than in the first realtime cycle."""
    _word_table()
