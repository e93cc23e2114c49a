"""One rule for which rig file a name means, and every place that finds one uses it."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from handrig.app.parts import build_parts
from handrig.app.sources import rig_file, run_sources
from handrig.config.paths import installed_config, user_config
from handrig.config.rig_files import RIGS_DIR, resolve_rig_file
from handrig.errors import ConfigError
from handrig.pose.robot_rig import find_rig, load_rig


def _user_rig(first_id: int) -> Path:
    """A rig.toml of the user's: the shipped one with its first servo's id changed, so a
    loaded config tells whose it is."""
    text = installed_config("rig.toml").read_text()
    mine = user_config("rig.toml")
    mine.parent.mkdir(parents=True, exist_ok=True)
    head, sep, rest = text.partition("[[servos]]\nid = ")
    assert sep, "the shipped rig.toml's first servo is no longer written as expected"
    _, _, tail = rest.partition("\n")
    mine.write_text(f"{head}{sep}{first_id}\n{tail}")
    return mine


def test_no_name_is_the_users_rig_then_the_shipped_one_everywhere() -> None:
    shipped = installed_config("rig.toml")
    assert resolve_rig_file(None).path == shipped
    assert "shipped default" in resolve_rig_file("").why
    assert find_rig(None)[0] == shipped
    mine = _user_rig(first_id=200)
    assert user_config("rig.toml").parent == Path(os.environ["XDG_CONFIG_HOME"]) / "handrig"
    found = resolve_rig_file(None)
    assert found.path == mine and "your rig.toml" in found.why
    # the loader, the factory, the run's sources and find_rig all read the same file
    assert load_rig(None).servos[0].id == 200
    assert find_rig(None)[0] == mine and find_rig(None)[1].servos[0].id == 200
    assert build_parts(None).rig_file == mine
    assert build_parts(None).rig_config.servos[0].id == 200
    assert rig_file(None).path == mine
    assert run_sources(None)[0].path == mine


def test_presets_paths_and_unknown_names(tmp_path: Path) -> None:
    leap = resolve_rig_file("leap")
    assert leap.path == RIGS_DIR / "leap.toml" and leap.preset == "leap"
    assert "preset 'leap'" in leap.why
    own = tmp_path / "mine.toml"
    assert resolve_rig_file(own).path == own and resolve_rig_file(str(own)).why == "--rig"
    assert resolve_rig_file("rigs/x.toml").path == Path("rigs/x.toml")
    with pytest.raises(ConfigError, match=r"no rig preset 'leapp'.*leap.*puppet_two_hands"):
        resolve_rig_file("leapp")
