"""Protocol 2.0 packets: CRC, instruction packets, status packets, Fast Sync Read replies.

The CRC is dynamixel-sdk's (``Protocol2PacketHandler.updateCRC``), computed by
the compiled ``fastcrc`` and checked against the SDK's own function at import. The
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

from collections.abc import Callable
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


def sdk_crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """The CRC as dynamixel-sdk computes it (``updateCRC``, a Python loop): the reference."""
    return int(_SDK_HANDLER.updateCRC(crc, list(bytes(data)), len(data)))


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-16 (poly 0x8005, init 0, not reflected: CRC-16/UMTS) of ``data``,
    continuing from ``crc``. Computed by ``fastcrc`` (compiled): a Python loop took
    4 us per 166-byte reply warm and 20-25 us in the realtime loop's cold cache,
    twice per cycle. Checked against the SDK's ``updateCRC`` at import."""
    return _umts(data, crc)


def _checked_umts() -> Callable[[bytes | bytearray | memoryview, int], int]:
    from fastcrc import crc16 as fast16

    umts: Callable[[bytes | bytearray | memoryview, int], int] = fast16.umts
    probe = bytes(range(256)) + b"\xff\xff\xfd\x00\xfe"
    for n, start in ((0, 0), (1, 0x1234), (7, 0), (77, 0xBEEF), (len(probe), 0)):
        if umts(probe[:n], start) != sdk_crc16(probe[:n], start):
            raise ImportError("fastcrc's CRC-16/UMTS disagrees with dynamixel-sdk's updateCRC")
    return umts


_umts = _checked_umts()


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
