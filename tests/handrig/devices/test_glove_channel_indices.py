"""Glove files whose raw channel indices repeat or leave a gap are refused naming the
entry's key (issue 41); OpenGloves letters may repeat (one thumb value drives three
curves)."""

from __future__ import annotations

from pathlib import Path

import pytest

from handrig.config.loading import CONFIG_DIR
from handrig.devices.glove_calibration import load_glove_config
from handrig.errors import ConfigError


def _channel(index: int, curve: str) -> str:
    return (f'[[channels]]\nindex = {index}\ncurve = "{curve}"\nraw_open = 1000\n'
            "raw_closed = 3000\nopen_deg = 0\nclosed_deg = 10\n")


@pytest.mark.parametrize(
    ("indices", "match"),
    [
        ((0, 1, 1), r"channels\[2\]\.index.*raw channel 1 already read by channels\[1\]"),
        ((0, 0), r"channels\[1\]\.index.*raw channel 0 already read by channels\[0\]"),
        ((0, 1, 3), r"channels\[2\]\.index.*raw channel 2 is read by no"),
        ((1, 2), r"channels\[1\]\.index.*raw channel 0 is read by no"),
    ],
)
def test_duplicated_or_missing_index_is_refused(tmp_path: Path, indices: tuple[int, ...],
                                                match: str) -> None:
    curves = ("riThumbCMCx", "riThumbCMCy", "riThumbCMCz")
    p = tmp_path / "glove.toml"
    p.write_text("".join(_channel(i, c) for i, c in zip(indices, curves, strict=False)))
    with pytest.raises(ConfigError, match=match) as e:
        load_glove_config(p)
    assert str(p) in str(e.value)


def test_shipped_gloves_load(tmp_path: Path) -> None:
    assert [c.index for c in load_glove_config(CONFIG_DIR / "glove.toml").channels] == [
        0, 1, 2, 3, 4]
    letters = [c.letter for c in load_glove_config(CONFIG_DIR / "glove_opengloves.toml").channels]
    assert letters.count("A") == 3
    p = tmp_path / "glove.toml"
    p.write_text(_channel(1, "riThumbCMCx") + _channel(0, "riThumbCMCy"))  # any order
    assert len(load_glove_config(p).channels) == 2
