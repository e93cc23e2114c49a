"""The glove frame, version 1: a pure codec (see ``firmware_protocol/SPEC.md``).

One frame carries one sample of a minimal glove: a sequence number, the sensor
timestamp, up to :data:`MAX_CHANNELS` raw sensor channels (uint16), the forearm
IMU orientation (int16 Q14 quaternion, scalar last, x y z w, world frame ENU)
and a buttons bitfield (bit 0 = relax / e-stop). The payload ends in a
CRC-16/CCITT-FALSE and is COBS-stuffed so that the byte 0x00 only ever appears
as the frame delimiter; a receiver that sees garbage resynchronises at the next
0x00. Everything is little-endian.

Pure code: no I/O, no clock. :class:`FrameDecoder` takes arbitrary byte chunks
(as a serial port returns them) and gives back whole frames, counting every
rejected byte.
"""

from __future__ import annotations

import binascii
import enum
import struct
from dataclasses import dataclass

from cobs import cobs

FRAME_VERSION = 1
"""The only version this codec reads and writes (payload byte 0)."""
MAX_CHANNELS = 16
"""Most raw sensor channels one frame may carry."""
DELIMITER = 0x00
"""Ends every frame on the wire (and may be repeated as idle fill)."""
Q14_ONE = 16384
"""A quaternion component of 1.0 in int16 Q14 fixed point (2**14)."""

FLAG_IMU_VALID = 0x01
"""Flags bit 0: the quaternion fields hold a valid orientation."""
FLAG_IMU_ABSENT = 0x02
"""Flags bit 1: no IMU answers (none found at start, or it stopped answering)."""
FLAG_IMU_UNCALIBRATED = 0x04
"""Flags bit 2: the IMU answers but its fusion is not calibrated yet."""
FLAG_SENSOR_RAIL = 0x08
"""Flags bit 3: a raw channel is pinned at 0 or full scale (a broken wire)."""
FLAG_WATCHDOG_RESET = 0x10
"""Flags bit 4: the firmware was restarted by its watchdog."""
FLAG_OVERRUN = 0x20
"""Flags bit 5: the glove missed a sample tick since the previous frame."""
STATUS_FLAGS = (FLAG_IMU_ABSENT | FLAG_IMU_UNCALIBRATED | FLAG_SENSOR_RAIL
                | FLAG_WATCHDOG_RESET | FLAG_OVERRUN)
"""The status bits of the flags byte (all but bit 0, which the quaternion implies)."""
BUTTON_RELAX = 0x01
"""Buttons bit 0: the relax / e-stop button is pressed."""

_HEADER = struct.Struct("<BBHIBB4h")  # version flags seq t_us buttons n_channels qx qy qz qw
_CRC = struct.Struct("<H")
HEADER_SIZE = _HEADER.size  # 18
CRC_SIZE = _CRC.size  # 2
MIN_PAYLOAD = HEADER_SIZE + CRC_SIZE
"""Payload bytes of a frame with no channels (20)."""
MAX_PAYLOAD = MIN_PAYLOAD + 2 * MAX_CHANNELS
"""Payload bytes of a frame with :data:`MAX_CHANNELS` channels (52)."""
MAX_ENCODED = MAX_PAYLOAD + 1
"""COBS adds exactly one byte to a payload shorter than 254 bytes (53, delimiter excluded)."""
SEQ_MODULO = 1 << 16
TIMESTAMP_MODULO = 1 << 32
_CHANNEL_STRUCTS = tuple(struct.Struct(f"<{n}H") for n in range(MAX_CHANNELS + 1))


def crc16_ccitt_false(data: bytes | bytearray | memoryview) -> int:
    """CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, xorout 0; check 0x29B1.

    ``binascii.crc_hqx`` is this CRC (MSB-first, poly 0x1021) with the init passed in.
    """
    return binascii.crc_hqx(data, 0xFFFF)


class ErrorKind(enum.Enum):
    """Why a frame was rejected."""

    COBS = "cobs"
    """The stuffing is invalid (a code byte points past the end, or a 0x00 inside)."""
    LENGTH = "length"
    """Too short, too long, or the length disagrees with the channel count."""
    CRC = "crc"
    """The CRC does not match: bytes were corrupted on the way."""
    VERSION = "version"
    """A version byte this codec does not read."""
    OVERFLOW = "overflow"
    """More than :data:`MAX_ENCODED` bytes arrived without a delimiter."""


class FrameError(ValueError):
    """A frame that cannot be decoded; ``kind`` says why."""

    def __init__(self, kind: ErrorKind, message: str) -> None:
        self.kind = kind
        super().__init__(message)


@dataclass(frozen=True, slots=True)
class GloveFrame:
    """One decoded glove frame (protocol version 1).

    ``channels`` are the raw uint16 sensor readings in the glove's declared order;
    ``quat_xyzw`` is the forearm IMU orientation (scalar last, rotates IMU-frame
    vectors into the ENU world frame), quantised to Q14, or ``None`` when the
    glove flags it invalid; ``buttons`` bit 0 is relax / e-stop. ``status``: the
    flags byte without bit 0 (``FLAG_IMU_ABSENT`` ... ``FLAG_OVERRUN``; bits 6-7 are
    kept as sent).
    """

    seq: int
    timestamp_us: int
    channels: tuple[int, ...]
    quat_xyzw: tuple[float, float, float, float] | None = None
    buttons: int = 0
    status: int = 0

    @property
    def relax(self) -> bool:
        """The relax / e-stop button (buttons bit 0) is pressed."""
        return bool(self.buttons & BUTTON_RELAX)


def _q14(v: float) -> int:
    return max(-32768, min(32767, round(v * Q14_ONE)))


def pack_payload(frame: GloveFrame) -> bytes:
    """The unstuffed payload of ``frame`` (header, channels, CRC), without COBS."""
    n = len(frame.channels)
    if n > MAX_CHANNELS:
        raise ValueError(f"{n} channels: a frame carries at most {MAX_CHANNELS}")
    if not 0 <= frame.buttons <= 0xFF:
        raise ValueError(f"buttons {frame.buttons} do not fit one byte")
    if not 0 <= frame.status <= 0xFF:
        raise ValueError(f"status {frame.status} does not fit one byte")
    if frame.quat_xyzw is None:
        flags, q = frame.status & ~FLAG_IMU_VALID, (0, 0, 0, 0)
    else:
        flags = (frame.status & ~FLAG_IMU_VALID) | FLAG_IMU_VALID
        qx, qy, qz, qw = frame.quat_xyzw
        q = (_q14(qx), _q14(qy), _q14(qz), _q14(qw))
    head = _HEADER.pack(
        FRAME_VERSION, flags, frame.seq % SEQ_MODULO, frame.timestamp_us % TIMESTAMP_MODULO,
        frame.buttons, n, *q,
    )
    try:
        body = head + _CHANNEL_STRUCTS[n].pack(*frame.channels)
    except struct.error:
        raise ValueError(f"channels {frame.channels} must be integers 0..65535") from None
    return body + _CRC.pack(crc16_ccitt_false(body))


def encode_frame(frame: GloveFrame) -> bytes:
    """``frame`` as it goes on the wire: COBS-stuffed payload followed by the 0x00 delimiter."""
    return bytes(cobs.encode(pack_payload(frame))) + b"\x00"


def unpack_payload(payload: bytes | bytearray | memoryview) -> GloveFrame:
    """Decode an unstuffed payload; raises :class:`FrameError` (never anything else)."""
    size = len(payload)
    if size < MIN_PAYLOAD:
        raise FrameError(ErrorKind.LENGTH, f"{size} bytes, shorter than {MIN_PAYLOAD}")
    if size > MAX_PAYLOAD:
        raise FrameError(ErrorKind.LENGTH, f"{size} bytes, longer than {MAX_PAYLOAD}")
    (crc_sent,) = _CRC.unpack_from(payload, size - CRC_SIZE)
    crc_seen = crc16_ccitt_false(payload[: size - CRC_SIZE])
    if crc_sent != crc_seen:
        raise FrameError(ErrorKind.CRC, f"CRC 0x{crc_sent:04x} sent, 0x{crc_seen:04x} computed")
    version, flags, seq, t_us, buttons, n, qx, qy, qz, qw = _HEADER.unpack_from(payload, 0)
    if version != FRAME_VERSION:
        raise FrameError(ErrorKind.VERSION, f"version {version}, this codec reads {FRAME_VERSION}")
    if n > MAX_CHANNELS or size != MIN_PAYLOAD + 2 * n:
        raise FrameError(ErrorKind.LENGTH, f"{n} channels declared in a {size}-byte payload")
    channels = _CHANNEL_STRUCTS[n].unpack_from(payload, HEADER_SIZE)
    quat = (
        (qx / Q14_ONE, qy / Q14_ONE, qz / Q14_ONE, qw / Q14_ONE)
        if flags & FLAG_IMU_VALID else None
    )
    return GloveFrame(seq, t_us, channels, quat, buttons, flags & ~FLAG_IMU_VALID)


def decode_frame(encoded: bytes | bytearray | memoryview) -> GloveFrame:
    """Decode one COBS-stuffed frame (delimiter stripped); raises :class:`FrameError`."""
    if len(encoded) > MAX_ENCODED:
        raise FrameError(ErrorKind.LENGTH, f"{len(encoded)} stuffed bytes, at most {MAX_ENCODED}")
    try:
        payload = cobs.decode(encoded)
    except cobs.DecodeError as exc:
        raise FrameError(ErrorKind.COBS, f"bad COBS stuffing: {exc}") from None
    return unpack_payload(payload)


@dataclass
class DecoderStats:
    """Counters of a :class:`FrameDecoder` since it was made (all monotonic).

    ``resyncs`` counts rejected segments (the decoder dropped bytes and picked up
    again at the next delimiter); ``garbage_bytes`` counts every byte dropped that
    way. ``seq_gaps`` counts frames whose sequence number was not the previous
    one plus one; ``frames_lost`` sums the sequence numbers skipped.
    """

    frames_ok: int = 0
    crc_errors: int = 0
    cobs_errors: int = 0
    length_errors: int = 0
    version_errors: int = 0
    overflows: int = 0
    resyncs: int = 0
    garbage_bytes: int = 0
    seq_gaps: int = 0
    frames_lost: int = 0

    @property
    def errors(self) -> int:
        """Rejected frames of every kind."""
        return (self.crc_errors + self.cobs_errors + self.length_errors + self.version_errors
                + self.overflows)


_COUNTER = {
    ErrorKind.CRC: "crc_errors",
    ErrorKind.COBS: "cobs_errors",
    ErrorKind.LENGTH: "length_errors",
    ErrorKind.VERSION: "version_errors",
    ErrorKind.OVERFLOW: "overflows",
}


class FrameDecoder:
    """Streaming decoder: feed any byte chunks, get whole frames back.

    ``feed(chunk)`` returns the frames completed by that chunk, in order. Bytes
    that do not form a valid frame are dropped up to the next 0x00 and counted in
    :attr:`stats`; the decoder never raises on input. A run of more than
    :data:`MAX_ENCODED` bytes without a delimiter is dropped at once (counted as
    one overflow) and the decoder discards until the next delimiter. Empty
    segments (repeated 0x00) are idle fill, not errors.

    A decoder that starts (or is :meth:`reset`) may join a stream in the middle of
    a frame, as a host does when it opens a glove that is already sending: the
    bytes before the first delimiter are the tail of a frame it never saw. If
    they do not decode they are dropped as ``garbage_bytes`` but not counted as
    an error (a monitor opened mid-frame must not report a CRC error).
    """

    def __init__(self) -> None:
        self.stats = DecoderStats()
        self._buf = bytearray()
        self._discarding = False
        self._last_seq: int | None = None
        self._joined = False  # a delimiter seen since start/reset: segments are whole
        self.last_error: FrameError | None = None

    def reset(self) -> None:
        """Forget a partial frame and the sequence history (counters are kept)."""
        self._buf.clear()
        self._discarding = False
        self._last_seq = None
        self._joined = False

    def feed(self, chunk: bytes | bytearray | memoryview) -> list[GloveFrame]:
        """Frames completed by ``chunk`` (possibly none)."""
        out: list[GloveFrame] = []
        data = chunk if type(chunk) is bytes else bytes(chunk)
        end = len(data)
        if (not self._buf and not self._discarding and 1 < end <= MAX_ENCODED + 1
                and data.find(b"\x00") == end - 1):
            self._segment(data[:-1], out)  # the usual read: exactly one whole frame
            self._joined = True
            return out
        start = 0
        while start < end:
            z = data.find(b"\x00", start)
            if z < 0:
                self._absorb(data, start, end)
                break
            self._absorb(data, start, z)
            self._segment_done(out)
            self._joined = True
            start = z + 1
        return out

    def _absorb(self, data: bytes, start: int, stop: int) -> None:
        if self._discarding:
            self.stats.garbage_bytes += stop - start
            return
        self._buf += data[start:stop]
        if len(self._buf) > MAX_ENCODED:
            self._reject(FrameError(ErrorKind.OVERFLOW, f"{len(self._buf)} bytes without a "
                                    f"delimiter (a frame is at most {MAX_ENCODED})"),
                         len(self._buf))
            self._buf.clear()
            self._discarding = True

    def _segment_done(self, out: list[GloveFrame]) -> None:
        if self._discarding:
            self._discarding = False
            return
        if not self._buf:
            return
        seg = bytes(self._buf)
        self._buf.clear()
        self._segment(seg, out)

    def _segment(self, seg: bytes, out: list[GloveFrame]) -> None:
        try:
            frame = decode_frame(seg)
        except FrameError as exc:
            if self._joined:
                self._reject(exc, len(seg) + 1)
            else:  # the tail of a frame sent before this decoder joined the stream
                self.stats.garbage_bytes += len(seg) + 1
            return
        s = self.stats
        s.frames_ok += 1
        if self._last_seq is not None:
            skipped = (frame.seq - self._last_seq - 1) % SEQ_MODULO
            if skipped:
                s.seq_gaps += 1
                if skipped < SEQ_MODULO // 2:  # else a repeat or a step back: nothing lost
                    s.frames_lost += skipped
        self._last_seq = frame.seq
        out.append(frame)

    def _reject(self, exc: FrameError, nbytes: int) -> None:
        s = self.stats
        name = _COUNTER[exc.kind]
        setattr(s, name, getattr(s, name) + 1)
        s.resyncs += 1
        s.garbage_bytes += nbytes
        self.last_error = exc
