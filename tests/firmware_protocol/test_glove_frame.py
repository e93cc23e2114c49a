"""The glove frame codec: golden bytes of SPEC.md, round trip, and fuzz properties."""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocol.glove import (
    MAX_CHANNELS,
    MAX_ENCODED,
    ErrorKind,
    FrameDecoder,
    FrameError,
    GloveFrame,
    crc16_ccitt_false,
    decode_frame,
    encode_frame,
    pack_payload,
    unpack_payload,
)

SPEC = Path(__file__).resolve().parents[2] / "firmware_protocol" / "SPEC.md"

GOLDEN = [
    (
        GloveFrame(1, 1000, (2048, 1024, 3072, 500, 3500), (0.0, 0.0, 0.0, 1.0), 0),
        "01 01 01 00 e8 03 00 00 00 05 00 00 00 00 00 00 00 40 00 08 00 04 00 0c f4 01 ac 0d"
        " cc df",
        "04 01 01 01 03 e8 03 01 01 02 05 01 01 01 01 01 01 02 40 02 08 02 04 08 0c f4 01 ac 0d"
        " cc df 00",
    ),
    (
        GloveFrame(65535, 4294967000, (0, 65535, 256), None, 1),
        "01 00 ff ff d8 fe ff ff 01 03 00 00 00 00 00 00 00 00 00 00 ff ff 00 01 6e ab",
        "02 01 09 ff ff d8 fe ff ff 01 03 01 01 01 01 01 01 01 01 01 03 ff ff 04 01 6e ab 00",
    ),
    (
        GloveFrame(42, 123456789, (1000, 2000, 3000, 100, 4095), (0.5, -0.5, 0.5, 0.5), 0b101),
        "01 01 2a 00 15 cd 5b 07 05 05 00 20 00 e0 00 20 00 20 e8 03 d0 07 b8 0b 64 00 ff 0f"
        " 27 10",
        "04 01 01 2a 07 15 cd 5b 07 05 05 02 20 02 e0 02 20 09 20 e8 03 d0 07 b8 0b 64 05 ff 0f"
        " 27 10 00",
    ),
]


def _ref_crc(data: bytes) -> int:
    """Bit-by-bit CRC-16/CCITT-FALSE, written from SPEC.md section 4."""
    crc = 0xFFFF
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def _ref_cobs(payload: bytes) -> bytes:
    """COBS as SPEC.md section 2 describes it (payloads < 254 bytes)."""
    out = bytearray()
    for group in (payload + b"\x00").split(b"\x00")[:-1]:
        out.append(len(group) + 1)
        out += group
    return bytes(out)


def test_crc_check_value() -> None:
    assert crc16_ccitt_false(b"123456789") == 0x29B1 == _ref_crc(b"123456789")


@pytest.mark.parametrize(("frame", "payload_hex", "wire_hex"), GOLDEN)
def test_golden_bytes(frame: GloveFrame, payload_hex: str, wire_hex: str) -> None:
    payload, wire = bytes.fromhex(payload_hex), bytes.fromhex(wire_hex)
    assert pack_payload(frame) == payload
    assert encode_frame(frame) == wire
    assert _ref_cobs(payload) + b"\x00" == wire
    assert _ref_crc(payload[:-2]) == int.from_bytes(payload[-2:], "little")
    assert decode_frame(wire[:-1]) == frame
    dec = FrameDecoder()
    assert dec.feed(wire) == [frame]


@pytest.mark.parametrize(("frame", "payload_hex", "wire_hex"), GOLDEN)
def test_golden_bytes_are_the_ones_in_the_spec(
    frame: GloveFrame, payload_hex: str, wire_hex: str
) -> None:
    spec = re.sub(r"\s+", " ", SPEC.read_text())
    assert f"payload {payload_hex}" in spec
    assert f"wire {wire_hex}" in spec


def test_each_rejection_kind_is_named() -> None:
    good = pack_payload(GOLDEN[0][0])
    with pytest.raises(FrameError) as e:
        unpack_payload(good[:-1])
    assert e.value.kind is ErrorKind.CRC
    with pytest.raises(FrameError) as e:
        unpack_payload(good[:10])
    assert e.value.kind is ErrorKind.LENGTH
    bad_version = b"\x02" + good[1:-2]
    with pytest.raises(FrameError) as e:
        unpack_payload(bad_version + crc16_ccitt_false(bad_version).to_bytes(2, "little"))
    assert e.value.kind is ErrorKind.VERSION
    lying_count = good[:9] + b"\x04" + good[10:-2]
    with pytest.raises(FrameError) as e:
        unpack_payload(lying_count + crc16_ccitt_false(lying_count).to_bytes(2, "little"))
    assert e.value.kind is ErrorKind.LENGTH
    with pytest.raises(FrameError) as e:
        decode_frame(b"\x09\x01\x02")
    assert e.value.kind is ErrorKind.COBS


def test_encoder_refuses_what_the_wire_cannot_carry() -> None:
    with pytest.raises(ValueError, match="at most 16"):
        encode_frame(GloveFrame(0, 0, tuple(range(17))))
    with pytest.raises(ValueError, match=r"0\.\.65535"):
        encode_frame(GloveFrame(0, 0, (70000,)))


def test_sequence_gaps_and_wrap() -> None:
    dec = FrameDecoder()
    frames = [GloveFrame(s, 0, (1,)) for s in (65534, 65535, 0, 1, 5, 6)]
    out = dec.feed(b"".join(encode_frame(f) for f in frames))
    assert out == frames
    assert dec.stats.seq_gaps == 1 and dec.stats.frames_lost == 3
    assert dec.stats.errors == 0


def test_overflow_without_delimiter_is_dropped_then_resyncs() -> None:
    dec = FrameDecoder()
    f = GOLDEN[0][0]
    assert dec.feed(b"\x55" * 200) == []
    assert dec.stats.overflows == 1
    assert dec.feed(b"\x55" * 10 + b"\x00" + encode_frame(f)) == [f]
    assert dec.stats.garbage_bytes == 210


# -- properties ------------------------------------------------------------

quats = st.one_of(
    st.none(),
    st.tuples(*[st.integers(-32768, 32767).map(lambda i: i / 16384)] * 4),
)
frames_st = st.builds(
    GloveFrame,
    seq=st.integers(0, 65535),
    timestamp_us=st.integers(0, 2**32 - 1),
    channels=st.lists(st.integers(0, 65535), max_size=MAX_CHANNELS).map(tuple),
    quat_xyzw=quats,
    buttons=st.integers(0, 255),
)


def _chunks(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts})
    edges = [0, *points, len(data)]
    return [data[a:b] for a, b in itertools.pairwise(edges)]


@settings(max_examples=150, deadline=None)
@given(frames=st.lists(frames_st, min_size=1, max_size=8), cuts=st.lists(st.integers(0, 999)))
def test_round_trip_through_any_chunking(frames: list[GloveFrame], cuts: list[int]) -> None:
    wire = b"".join(encode_frame(f) for f in frames)
    assert all(len(encode_frame(f)) <= MAX_ENCODED + 1 for f in frames)
    assert all(b"\x00" not in encode_frame(f)[:-1] for f in frames)
    dec = FrameDecoder()
    out: list[GloveFrame] = []
    for c in _chunks(wire, cuts):
        out += dec.feed(c)
    assert out == frames
    assert dec.stats.frames_ok == len(frames) and dec.stats.errors == 0


@settings(max_examples=200, deadline=None)
@given(garbage=st.binary(max_size=400), cuts=st.lists(st.integers(0, 999), max_size=6))
def test_random_garbage_never_crashes_and_is_counted(garbage: bytes, cuts: list[int]) -> None:
    dec = FrameDecoder()
    out: list[GloveFrame] = []
    for c in _chunks(garbage, cuts):
        out += dec.feed(c)
    s = dec.stats
    assert s.frames_ok == len(out)
    # every byte is accounted for: a decoded frame, idle fill, dropped garbage or still buffered
    assert s.garbage_bytes <= len(garbage)
    assert s.resyncs == s.errors


@settings(max_examples=200, deadline=None)
@given(garbage=st.binary(max_size=300), after=st.lists(frames_st, min_size=1, max_size=4))
def test_resynchronises_at_the_next_delimiter(
    garbage: bytes, after: list[GloveFrame]
) -> None:
    dec = FrameDecoder()
    dec.feed(garbage)
    out = dec.feed(b"\x00" + b"".join(encode_frame(f) for f in after))
    # the garbage's last segment ends at that 0x00; nothing after it is lost
    assert out[-len(after):] == after


@settings(max_examples=200, deadline=None)
@given(
    frames=st.lists(frames_st, min_size=2, max_size=5),
    which=st.integers(0, 99),
    keep=st.integers(0, 99),
)
def test_a_truncated_frame_costs_at_most_the_next_one(
    frames: list[GloveFrame], which: int, keep: int
) -> None:
    wires = [encode_frame(f) for f in frames]
    i = which % (len(frames) - 1)
    kept = keep % len(wires[i])
    wires[i] = wires[i][:kept]  # cut before its delimiter: it merges with frame i + 1
    dec = FrameDecoder()
    # joined at a delimiter: from there on every bad segment is an error
    out = dec.feed(b"\x00" + b"".join(wires))
    assert out[:i] == frames[:i]
    tail = frames[i + 2:]
    assert out[len(out) - len(tail):] == tail
    assert len(out) in (len(frames) - 2, len(frames) - 1)
    if kept:
        assert dec.stats.errors == 1 and len(out) == len(frames) - 2


@settings(max_examples=300, deadline=None)
@given(frames=st.lists(frames_st, min_size=1, max_size=4), bit=st.integers(0, 10_000))
def test_a_bit_flip_never_forges_a_frame(frames: list[GloveFrame], bit: int) -> None:
    wire = bytearray(b"".join(encode_frame(f) for f in frames))
    pos = bit % (len(wire) * 8)
    wire[pos // 8] ^= 1 << (pos % 8)
    dec = FrameDecoder()
    out = dec.feed(b"\x00" + bytes(wire))  # joined at a delimiter, as the glove starts
    assert set(out) <= set(frames)
    assert len(out) < len(frames)
    if pos // 8 < len(wire) - 1:  # a flip in the very last delimiter only holds the frame back
        assert dec.stats.errors >= 1


@settings(max_examples=200, deadline=None)
@given(frames=st.lists(frames_st, min_size=2, max_size=5), cut=st.integers(1, 999))
def test_joining_a_stream_mid_frame_is_not_an_error(frames: list[GloveFrame], cut: int) -> None:
    # a host that opens a glove already sending sees the tail of a frame first
    wires = [encode_frame(f) for f in frames]
    head = wires[0][cut % (len(wires[0]) - 1) + 1:]  # a proper tail, ending at its 0x00
    dec = FrameDecoder()
    out = dec.feed(head + b"".join(wires[1:]))
    assert out[-(len(frames) - 1):] == frames[1:]
    assert dec.stats.errors == 0 and dec.stats.resyncs == 0
    # after that first delimiter a bad segment is an error again, and so after a reset
    bad = bytearray(wires[1])
    bad[1] ^= 0x01 if bad[1] != 0x01 else 0x02
    dec.feed(bytes(bad))
    assert dec.stats.errors == 1
    dec.reset()
    dec.feed(head)
    assert dec.stats.errors == 1
    dec.feed(bytes(bad))  # joined again at the tail's delimiter
    assert dec.stats.errors == 2
    # an overflow before any delimiter is an error; after its delimiter, bad counts
    fresh = FrameDecoder()
    fresh.feed(b"\x01" * 300 + b"\x00")
    assert fresh.stats.overflows == 1
    fresh.feed(bytes(bad))
    assert fresh.stats.errors == 2
