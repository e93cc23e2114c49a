"""The show file's cue tables, ``[osc]``, ``[midi]`` and ``[cues]``: loaded, and every key
checked (an error names the file and the key)."""

from __future__ import annotations

from pathlib import Path

import pytest

from handrig.config.cues import cue_words, parse_listen_address
from handrig.config.show import load_show
from handrig.errors import ConfigError

HEAD = '[show]\nrig = "puppet_two_hands"\n'


def _show(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "show.toml"
    p.write_text(HEAD + text)
    return p


def test_the_cue_tables_load_with_the_takes_folder_beside_the_show(tmp_path: Path) -> None:
    show = load_show(_show(tmp_path, '[osc]\nin = "0.0.0.0:9000"\n[midi]\nport = "nanoKEY"\n'
                           'channel = 10\nnote.60 = "relax"\ncc.21 = "layer intro le"\n'
                           '[cues]\ntakes = "takes"\n'))
    assert show.osc.in_ == "0.0.0.0:9000"
    assert show.midi.port == "nanoKEY" and show.midi.channel == 10
    assert show.midi.cues() == {("note", 60): ("relax", ()),
                                ("cc", 21): ("layer", ("intro", "le"))}
    assert show.cues.takes == str(tmp_path / "takes")


@pytest.mark.parametrize(("text", "key", "says"), [
    ('[osc]\nin = "nine"\n', "osc.in", "not an address"),
    ('[osc]\nin = 9000\n', "osc.in", "expected a string"),
    ('[osc]\nout = "9000"\n', "osc.out", "unknown key"),
    ('[midi]\nchannel = 17\n', "midi.channel", "not a MIDI channel"),
    ('[midi]\nnote.60 = "dance"\n', "midi.note.60", "not a cue"),
    ('[midi]\nnote.60 = "play"\n', "midi.note.60", "play takes 1 argument(s), got 0"),
    ('[midi]\ncc.7 = "layer intro"\n', "midi.cc.7", "layer takes 2 argument(s)"),
    ('[midi]\nnote.128 = "stop"\n', "midi.note.128", "not a MIDI note number"),
    ('[midi]\nnote.C4 = "stop"\n', "midi.note.C4", "not a MIDI note number"),
    ('[midi]\npitch.1 = "stop"\n', "midi.pitch", "unknown key"),
    ('[cues]\ntakes = 3\n', "cues.takes", "expected a string"),
])
def test_a_bad_cue_key_names_the_file_and_the_key(tmp_path: Path, text: str, key: str,
                                                  says: str) -> None:
    p = _show(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        load_show(p)
    assert err.value.key == key and err.value.file == str(p)
    assert says in str(err.value) and str(p) in str(err.value)


def test_listen_addresses_default_to_the_loopback() -> None:
    assert parse_listen_address("9000") == ("127.0.0.1", 9000)
    assert parse_listen_address("0.0.0.0:9001") == ("0.0.0.0", 9001)
    assert parse_listen_address("[::1]:9002") == ("::1", 9002)
    with pytest.raises(ConfigError, match="--osc-in 'x:70000'"):
        parse_listen_address("x:70000")


def test_cue_words_count_the_arguments() -> None:
    assert cue_words("record/start") == ("record/start", ())
    assert cue_words("record/start act1") == ("record/start", ("act1",))
    with pytest.raises(ConfigError, match="record/start takes 0 or 1"):
        cue_words("record/start a b")
