"""Cues without a loop: OSC 1.0 parsing (checked against python-osc's builder, an encoder
that is not ours), OSC and MIDI messages read as cues, the dispatcher acting on a
recording stand-in of the session's controls and the layers, and the cue takes."""

from __future__ import annotations

import struct
import sys
from pathlib import Path

import mido
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

from handrig.app.cues.dispatch import Cue, CueDispatcher, CueLog, CueTargets, osc_cue
from handrig.app.cues.midi import MidiCues
from handrig.app.cues.osc import OscMessage, encode_bundle, encode_message, parse_packet
from handrig.app.cues.receiver import OscReceiver
from handrig.app.cues.takes import CueTakes
from handrig.clock import FakeClock
from handrig.config.cues import ShowMidi
from handrig.errors import ConfigError, DataError
from handrig.outputs.recorder import load_performance
from handrig.pose.pipeline import POSE_NAMES


def _built(address: str, *args: object) -> bytes:
    b = OscMessageBuilder(address=address)
    for a in args:
        if isinstance(a, tuple):  # (value, python-osc's type tag)
            b.add_arg(*a)
        else:
            b.add_arg(a)
    return b.build().dgram


def test_messages_built_by_python_osc_parse_to_their_values() -> None:
    msgs, bad = parse_packet(_built("/handrig/layer", "intro", "le"))
    assert (msgs, bad) == ([OscMessage("/handrig/layer", ("intro", "le"))], 0)
    msgs, bad = parse_packet(_built("/x", 7, -3, 0.5, "abc"))
    assert msgs == [OscMessage("/x", (7, -3, 0.5, "abc"))] and bad == 0
    assert parse_packet(_built("/handrig/relax")) == ([OscMessage("/handrig/relax")], 0)


def test_a_bundle_and_a_nested_one_give_their_messages_in_order() -> None:
    inner = OscBundleBuilder(IMMEDIATELY)
    inner.add_content(OscMessageBuilder("/handrig/resume").build())
    outer = OscBundleBuilder(IMMEDIATELY)
    outer.add_content(OscMessageBuilder("/handrig/relax").build())
    outer.add_content(inner.build())
    outer.add_content(_osc_message("/handrig/stop"))
    msgs, bad = parse_packet(outer.build().dgram)
    assert [m.address for m in msgs] == ["/handrig/relax", "/handrig/resume", "/handrig/stop"]
    assert bad == 0


def _osc_message(address: str) -> object:
    return OscMessageBuilder(address).build()


@pytest.mark.parametrize("data", [
    b"garbage!",  # no address
    b"/abc",  # no NUL
    b"/handrig/relax\x00\x00",  # no type tags, and not a multiple of 4
    encode_message("/handrig/relax")[:16],  # no type tag string
    _built("/handrig/play", b"\x01\x02"),  # a blob: not a type cues take
    _built("/handrig/play", True),  # T
    _built("/handrig/play", (3.5, "d")),  # a double
    _built("/handrig/play", (7, "h")),  # a 64-bit integer
    _built("/handrig/play", (0x11223344, "r")),  # an RGBA colour: 4 bytes, as i and f
    b"/h\x00\x00,c\x00\x00\x00\x00\x00A",  # a char: 4 bytes
    encode_message("/handrig/play", 3)[:-2],  # cut inside its argument
    encode_message("/handrig/play", 3) + b"\x00\x00\x00\x00",  # bytes after the arguments
    b"/h\x00\x01,\x00\x00\x00",  # padding that is not NULs
])
def test_what_cues_do_not_take_is_one_malformed_message(data: bytes) -> None:
    assert parse_packet(data) == ([], 1)


def test_a_bad_element_loses_only_itself_a_bad_frame_the_rest() -> None:
    good = encode_message("/handrig/stop")
    msgs, bad = parse_packet(encode_bundle(encode_message("/handrig/relax"), b"junk", good))
    assert [m.address for m in msgs] == ["/handrig/relax", "/handrig/stop"] and bad == 1
    # an element size past the end: the rest cannot be framed
    broken = encode_bundle(good) + struct.pack(">i", 400) + good
    msgs, bad = parse_packet(broken)
    assert [m.address for m in msgs] == ["/handrig/stop"] and bad == 1


@given(st.text(alphabet=st.characters(min_codepoint=33, max_codepoint=126), max_size=20),
       st.lists(st.one_of(st.integers(-2**31 + 1, 2**31 - 1), st.text(
           alphabet=st.characters(min_codepoint=32, max_codepoint=126), max_size=12)),
                max_size=5))
def test_round_trip_against_python_osc(tail: str, args: list[int | str]) -> None:
    # (python-osc writes -2**31 as a 64-bit "h"; cues take 32-bit "i" only)
    address = "/" + tail
    ours = encode_message(address, *args)
    assert ours == _built(address, *args)
    assert parse_packet(ours) == ([OscMessage(address, tuple(args))], 0)


@pytest.mark.parametrize(("msg", "read"), [
    (OscMessage("/handrig/relax"), Cue("relax")),
    (OscMessage("/handrig/estop", (1.0,)), Cue("estop")),  # a surface's button pressed
    (OscMessage("/handrig/estop", (0.0,)), "released"),  # ... and let go
    (OscMessage("/handrig/record/start"), Cue("record/start")),
    (OscMessage("/handrig/record/start", ("act1",)), Cue("record/start", ("act1",))),
    (OscMessage("/handrig/layer", ("intro", "le")), Cue("layer", ("intro", "le"))),
    (OscMessage("/handrig/dance"), "unknown"),
    (OscMessage("/other/relax"), "unknown"),
    (OscMessage("/handrig/play"), "malformed"),
    (OscMessage("/handrig/play", (3,)), "malformed"),
    (OscMessage("/handrig/play", ("two words",)), "malformed"),
    (OscMessage("/handrig/layer", ("intro",)), "malformed"),
    (OscMessage("/handrig/stop", ("now", "please")), "malformed"),
])
def test_osc_messages_read_as_cues(msg: OscMessage, read: object) -> None:
    assert osc_cue(msg) == read


class Recorded:
    """The session's controls and the layers, as calls written down."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, ...]] = []

    def targets(self, *, layers: bool = True) -> CueTargets:
        def note(name: str) -> object:
            return lambda *args: self.calls.append((name, *args))

        def play(name: str) -> None:
            if name == "nosuch":
                raise ConfigError("no such take", key="play", value=name)
            self.calls.append(("play", name))

        def layer(name: str, group: str) -> None:
            self.calls.append(("layer", name, group))

        return CueTargets(relax=note("relax"), resume=note("resume"),  # type: ignore[arg-type]
                          stop=note("stop"), estop=note("estop"),  # type: ignore[arg-type]
                          record_start=lambda name: f"recording {name}",
                          record_stop=lambda: "closed",
                          play=play if layers else None, layer=layer if layers else None)


def test_the_dispatcher_acts_names_the_source_and_refuses_what_fails() -> None:
    rec, clock = Recorded(), FakeClock()
    log = CueLog(clock)
    lines: list[str] = []
    d = CueDispatcher(rec.targets(), log, on_event=lines.append)
    for cue in (Cue("relax"), Cue("resume", (), "MIDI"), Cue("play", ("intro",)),
                Cue("layer", ("intro", "le")), Cue("play", ("nosuch",)),
                Cue("record/start", ("act1",)), Cue("record/stop"), Cue("stop")):
        d.dispatch(cue)
    assert rec.calls == [("relax", "relax (OSC)"), ("resume", "resume (MIDI)"),
                         ("play", "intro"), ("layer", "intro", "le"), ("stop", "stop (OSC)")]
    s = log.summary()
    assert s["acted"] == 7 and s["refused"] == 1
    assert any("play nosuch (OSC) refused: play = 'nosuch': no such take" in e
               for e in s["events"])
    assert "record/start act1 (OSC): recording act1" in log.recent()
    assert len(lines) == 8


def test_without_layers_play_and_layer_are_refused_not_lost() -> None:
    log = CueLog(FakeClock())
    d = CueDispatcher(Recorded().targets(layers=False), log)
    d.dispatch(Cue("play", ("intro",)))
    d.dispatch(Cue("layer", ("intro", "le")))
    assert log.counts["refused"] == 2 and "no layering" in log.summary()["events"][0]


def test_the_osc_port_counts_what_is_no_cue() -> None:
    rec = Recorded()
    log = CueLog(FakeClock())
    port = OscReceiver("127.0.0.1", 0, CueDispatcher(rec.targets(), log))
    try:
        port.handle(encode_bundle(encode_message("/handrig/relax"), b"junk"))
        port.handle(encode_message("/handrig/nope"))
        port.handle(encode_message("/handrig/play", 1))
        port.handle(encode_message("/handrig/estop", 0))
    finally:
        port.close()
    assert log.counts == {"received": 5, "acted": 1, "refused": 0, "unknown": 1,
                          "malformed": 2, "unmapped": 0, "released": 1}
    assert rec.calls == [("relax", "relax (OSC)")]


def test_midi_notes_and_controllers_map_to_cues_on_their_channel() -> None:
    cues = MidiCues(ShowMidi(channel=2, note={"60": "relax", "62": "play intro"},
                             cc={"20": "stop"}))
    ch = 1  # mido counts from 0: the show file's channel 2
    assert cues.cue(mido.Message("note_on", channel=ch, note=60, velocity=90)) == Cue(
        "relax", (), "MIDI")
    assert cues.cue(mido.Message("note_on", channel=ch, note=62, velocity=1)) == Cue(
        "play", ("intro",), "MIDI")
    assert cues.cue(mido.Message("note_on", channel=ch, note=60, velocity=0)) is None
    assert cues.cue(mido.Message("note_off", channel=ch, note=60)) is None
    assert cues.cue(mido.Message("note_on", channel=0, note=60, velocity=90)) is None
    assert cues.cue(mido.Message("note_on", channel=ch, note=61, velocity=90)) == "unmapped"
    assert cues.cue(mido.Message("program_change", channel=ch, program=3)) == "unmapped"
    assert cues.cue(mido.Message("clock")) is None
    # a controller acts once as it rises past 64, again only after falling below
    values = [0, 70, 127, 100, 10, 64]
    got = [cues.cue(mido.Message("control_change", channel=ch, control=20, value=v))
           for v in values]
    assert got == [None, Cue("stop", (), "MIDI"), None, None, None, Cue("stop", (), "MIDI")]


def test_midi_handling_counts_and_dispatches() -> None:
    rec = Recorded()
    log = CueLog(FakeClock())
    d = CueDispatcher(rec.targets(), log)
    cues = MidiCues(ShowMidi(note={"60": "estop"}))  # channel 0: every channel
    for msg in (mido.Message("note_on", channel=9, note=60, velocity=100),
                mido.Message("note_on", channel=3, note=50, velocity=100),
                mido.Message("active_sensing")):
        cues.handle(msg, d)
    assert rec.calls == [("estop", "estop (MIDI)")]
    assert log.counts["received"] == 2 and log.counts["unmapped"] == 1
    assert log.by_source == {"MIDI": 2}


def test_cue_takes_start_stop_and_never_replace(tmp_path: Path) -> None:
    takes = CueTakes(tmp_path / "takes", 100.0)  # made on the first take
    pose = np.zeros(len(POSE_NAMES))
    takes(5.0, pose)  # no take open: nothing happens
    assert "recording" in takes.start("act1")
    with pytest.raises(DataError, match="recording already"):
        takes.start("act2")
    for k in range(10):
        takes(10.0 + k / 100, pose)
    assert "10 frames" in takes.stop()
    t_s, _, _ = load_performance(tmp_path / "takes" / "act1.csv")
    assert len(t_s) == 10 and t_s[0] == 0.0  # the take starts at 0
    with pytest.raises(DataError, match="never replaced"):
        takes.start("act1.csv")
    with pytest.raises(DataError, match="not a take's name"):
        takes.start("../act1")
    with pytest.raises(DataError, match="no take is recording"):
        takes.stop()
    generated = takes.path_for(None)
    assert generated.parent == tmp_path / "takes" and generated.name.startswith("take-")
    takes.start(None)
    takes(1.0, pose)
    assert takes.close().startswith("take ")  # the run's end closes it
    assert takes.summary()["recording"] == "" and len(takes.summary()["done"]) == 2


def test_another_programs_address_is_unknown_without_a_parse() -> None:
    log = CueLog(FakeClock())
    port = OscReceiver("127.0.0.1", 0, CueDispatcher(Recorded().targets(), log))
    try:
        port.handle(encode_message("/eos/out/cue", 3))
        port.handle(encode_message("/handrigx/relax"))
        port.handle(encode_message("/handrig/relax"))
    finally:
        port.close()
    assert (log.counts["unknown"], log.counts["acted"], log.counts["received"]) == (2, 1, 3)


def test_a_flood_of_what_is_no_cue_is_said_five_times_then_counted() -> None:
    log = CueLog(FakeClock())
    lines: list[str] = []
    port = OscReceiver("127.0.0.1", 0, CueDispatcher(Recorded().targets(), log,
                                                     on_event=lines.append))
    try:
        for _ in range(1000):
            port.handle(encode_message("/handrig/level", 0.5))
        port.handle(b"junk")
    finally:
        port.close()
    assert log.counts["unknown"] == 1000 and log.counts["malformed"] == 1
    assert len(lines) == 6 and "counted only" in lines[4]


def test_without_python_rtmidi_midi_cues_say_how_to_get_it(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from handrig.app.cues.midi import check_midi

    check_midi()  # the dev install has the show extra
    monkeypatch.setitem(sys.modules, "rtmidi", None)  # as if not installed
    with pytest.raises(ConfigError, match=r"--midi-in: .*pip install 'handrig\[show\]'"):
        check_midi()



def test_a_port_in_use_and_bad_flags_are_said_before_anything_starts(
        capsys: pytest.CaptureFixture[str]) -> None:
    import socket

    from handrig.cli import main

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        with pytest.raises(ConfigError, match=f"--osc-in '127.0.0.1:{port}': cannot listen"):
            OscReceiver("127.0.0.1", port, CueDispatcher(Recorded().targets(),
                                                         CueLog(FakeClock())))
    assert main(["play", "take.csv", "--osc-in", "9000"]) == 2
    assert "--osc-in '9000': only with --bus" in capsys.readouterr().err
    assert main(["run", "--bus", "sim", "--osc-in", "nine"]) == 2
    assert "--osc-in 'nine': not an address to listen on" in capsys.readouterr().err
