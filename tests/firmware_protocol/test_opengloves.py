"""OpenGloves alpha lines: golden lines, rejections, round trip and fuzz."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocol.opengloves import (
    CHANNEL_KEYS,
    LineDecoder,
    LineError,
    LineErrorKind,
    OpenGlovesLine,
    encode_force_feedback,
    encode_line,
    parse_line,
)

N = None


def test_golden_full_line_esp32() -> None:
    line = parse_line(b"A0B512C1023D4095E100F2048G1000P300\n", 4095)
    assert line.fingers == (0, 512, 1023, 4095, 100)
    assert line.joystick == (2048, 1000) and line.trigger == 300
    assert line.buttons == frozenset() and line.splay == (N, N, N, N, N)
    assert encode_line(line) == b"A0B512C1023D4095E100F2048G1000P300\n"


def test_golden_buttons() -> None:
    line = parse_line("A10B20C30D40E50F0G1023P1023HIJN\r\n", 1023)
    assert line.buttons == frozenset("HIJN")
    assert line.button_bits() == 0b0100_0111
    assert encode_line(line) == b"A10B20C30D40E50F0G1023P1023HIJN\n"


def test_golden_splay_and_joints() -> None:
    text = "A1B2C3D4E5(AB)2048(BB)0(CB)4095(DB)1(EB)2(AAA)10(AAD)11(EAD)20\n"
    line = parse_line(text)
    assert line.splay == (2048, 0, 4095, 1, 2)
    assert line.joints[0] == (10, N, N, 11) and line.joints[4] == (N, N, N, 20)
    assert line.joints[2] == (N, N, N, N)
    assert encode_line(line).decode() == text
    ch = line.channels(4095)
    assert len(ch) == len(CHANNEL_KEYS) == 13
    assert ch[:10] == (1, 2, 3, 4, 5, 2048, 0, 4095, 1, 2)
    assert ch[10:] == (2047.5, 2047.5, 0.0)  # absent joystick neutral, trigger 0


@pytest.mark.parametrize(
    ("text", "kind"),
    [
        ("A512B300C0", LineErrorKind.MISSING),  # cut: D and E never came
        ("A512B300C0D1E", LineErrorKind.MISSING),  # cut inside a key
        ("A1B2C3D4E5F6G7P8A1B2C3D4E5", LineErrorKind.DUPLICATE),  # two lines merged
        ("A1B2C3D4E5HH", LineErrorKind.DUPLICATE),
        ("A1B2C3D4E5x", LineErrorKind.SYNTAX),
        ("A1B2C3D4E5Q7", LineErrorKind.SYNTAX),
        ("A1B2C3D4E5H3", LineErrorKind.SYNTAX),
        ("A1B2C3D4E5(AB)", LineErrorKind.SYNTAX),
        ("A1B2C3D4E5(FB)3", LineErrorKind.SYNTAX),
        ("A1B2C3D4E4096", LineErrorKind.RANGE),
        ("A1B2C3D4E99999999999999", LineErrorKind.RANGE),
        (b"A1B2C3D4E5\xff", LineErrorKind.SYNTAX),
    ],
)
def test_malformed_lines_are_rejected_by_kind(text: str | bytes, kind: LineErrorKind) -> None:
    with pytest.raises(LineError) as e:
        parse_line(text, 4095)
    assert e.value.kind is kind


def test_analog_max_1023_rejects_esp32_values() -> None:
    with pytest.raises(LineError):
        parse_line("A2000B0C0D0E0", 1023)
    assert parse_line("A2000B0C0D0E0", 4095).fingers[0] == 2000


def test_stream_counts_cut_and_merged_lines_and_keeps_the_good_ones() -> None:
    dec = LineDecoder(1023)
    stream = (b"3D4E5\n"  # joined mid-line: cut
              b"A1B2C3D4E5F0G0P0\n"
              b"A9B9C9\n"  # cut
              b"A1B2C3D4E5A1B2C3D4E5\n"  # merged
              b"\n\r\n"  # blank: ignored
              b"A7B7C7D7E7\n"
              b"A8")
    out = []
    for i in range(0, len(stream), 5):
        out += dec.feed(stream[i:i + 5])
    assert [o.fingers for o in out] == [(1, 2, 3, 4, 5), (7, 7, 7, 7, 7)]
    s = dec.stats
    assert (s.lines_ok, s.cut_lines, s.merged_lines, s.errors) == (2, 2, 1, 3)
    assert dec.feed(b"B8C8D8E8\n")[0].fingers == (8, 8, 8, 8, 8)


def test_overlong_run_is_dropped_up_to_the_next_newline() -> None:
    dec = LineDecoder()
    assert dec.feed(b"A" * 1000) == []
    assert dec.feed(b"B" * 10 + b"\nA1B1C1D1E1\n")[0].fingers == (1, 1, 1, 1, 1)
    assert dec.stats.overflows == 1 and dec.stats.garbage_bytes == 1010


def test_force_feedback_line() -> None:
    assert encode_force_feedback((0, 250, 500, 750, 1000)) == b"A0B250C500D750E1000\n"
    with pytest.raises(ValueError):
        encode_force_feedback((0, 0, 0, 0, 1001))


values = st.integers(0, 4095)
opt = st.one_of(st.none(), values)
lines_st = st.builds(
    OpenGlovesLine,
    fingers=st.tuples(values, values, values, values, values),
    joystick=st.one_of(st.none(), st.tuples(values, values)),
    trigger=opt,
    buttons=st.frozensets(st.sampled_from("HIJKLMNO")),
    splay=st.tuples(opt, opt, opt, opt, opt),
    joints=st.tuples(*[st.tuples(opt, opt, opt, opt)] * 5),
)


@settings(max_examples=150, deadline=None)
@given(lines=st.lists(lines_st, min_size=1, max_size=5), step=st.integers(1, 40))
def test_round_trip_through_the_stream(lines: list[OpenGlovesLine], step: int) -> None:
    wire = b"".join(encode_line(x) for x in lines)
    dec = LineDecoder(4095)
    out = []
    for i in range(0, len(wire), step):
        out += dec.feed(wire[i:i + step])
    assert out == lines and dec.stats.errors == 0


@settings(max_examples=200, deadline=None)
@given(garbage=st.binary(max_size=600), good=lines_st)
def test_garbage_never_crashes_and_the_next_line_parses(
    garbage: bytes, good: OpenGlovesLine
) -> None:
    dec = LineDecoder(4095)
    out = dec.feed(garbage)
    assert dec.stats.lines_ok == len(out)
    assert dec.stats.garbage_bytes <= len(garbage)
    assert dec.feed(b"\n" + encode_line(good))[-1] == good
