"""The show file's [timecode] table: checked on load, an error naming the file and the
key; a WAV relative to the show file's folder."""

from __future__ import annotations

from pathlib import Path

import pytest

from handrig.config.show import load_show
from handrig.errors import ConfigError

HEAD = '[show]\nrig = "puppet_two_hands"\n[timecode]\n'
EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "show.toml"


@pytest.mark.parametrize(("text", "key", "says"), [
    ('source = "tc.mp3"\n', "timecode.source", "not an LTC source"),
    ('source = "none.wav"\n', "timecode.source", "no such file"),
    ('fps = "23.976"\n', "timecode.fps", "not a timecode rate"),
    ('fps = 25\n', "timecode.fps", ""),
    ('sourse = "tc.wav"\n', "timecode.sourse", "unknown key"),
])
def test_a_bad_timecode_table_names_the_file_and_the_key(tmp_path: Path, text: str, key: str,
                                                        says: str) -> None:
    path = tmp_path / "show.toml"
    path.write_text(HEAD + text)
    with pytest.raises(ConfigError) as err:
        load_show(path)
    message = str(err.value)
    assert str(path) in message and key in message and says in message, message


def test_the_timecode_source_is_found_beside_the_show(tmp_path: Path) -> None:
    (tmp_path / "audio").mkdir()
    (tmp_path / "audio" / "ltc.wav").write_bytes(b"")
    path = tmp_path / "show.toml"
    path.write_text(HEAD + 'source = "audio/ltc.wav"\nfps = "29.97"\n')
    show = load_show(path)
    assert show.timecode.source == str(tmp_path / "audio" / "ltc.wav")
    assert show.timecode.fps == "29.97"
    path.write_text(HEAD + 'source = "alsa:hw:1,0"\n')
    assert load_show(path).timecode.source == "alsa:hw:1,0"
    example = load_show(EXAMPLE)
    assert example.timecode.source == "" and example.timecode.fps == "auto"
