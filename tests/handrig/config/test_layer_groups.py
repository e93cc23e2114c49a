"""Layer groups, ``--layer TAKE:GROUP`` and the show file's ``[takes]`` and ``[[layer]]``
(issue 40): every name a puppeteer may write, and a clear error naming the allowed
ones for anything else."""

from __future__ import annotations

from pathlib import Path

import pytest

from handrig import hand
from handrig.app.layering import parse_layer_flag
from handrig.config.layer_groups import group_joints
from handrig.config.show import load_show
from handrig.errors import ConfigError

BOTH = ("ri", "le")


def test_hands_fingers_wrists_and_curves() -> None:
    left = group_joints("left", BOTH)
    assert len(left) == 27 and all(n.startswith("le") for n in left)
    assert "leWristFlexion" in left and "leWristDeviation" in left
    assert group_joints("all", BOTH) == hand.ALL_JOINT_NAMES
    assert group_joints("left.index", BOTH) == tuple(
        f"leIndex{j}{a}" for j, a in hand.FINGER_JOINTS)
    assert group_joints("right.little", BOTH)[0] == "riPinkyMCPx"
    assert group_joints("right.wrist", BOTH) == ("riWristFlexion", "riWristDeviation")
    # a one-hand puppet: the bare finger is its hand's
    assert group_joints("thumb", ("ri",)) == tuple(c.name for c in hand.select_curves(
        "ri", "Thumb"))
    # a comma list of any of these, in the full pose's order, once each
    mixed = group_joints("riIndexPIPy, right.index ,leWristFlexion", BOTH)
    assert mixed == (*(f"riIndex{j}{a}" for j, a in hand.FINGER_JOINTS), "leWristFlexion")


@pytest.mark.parametrize(("group", "hands", "said"), [
    ("index", BOTH, "left.index or right.index"),
    ("left", ("ri",), "no left hand"),
    ("riIndexPIP", BOTH, "unknown group 'riIndexPIP'"),
    ("middle.left", BOTH, "unknown group"),
    ("", BOTH, "an empty group"),
    ("left,,index", BOTH, "an empty group"),
])
def test_an_unknown_group_names_what_is_allowed(group: str, hands: tuple[str, ...],
                                                said: str) -> None:
    with pytest.raises(ConfigError) as err:
        group_joints(group, hands, key="--layer")
    text = str(err.value)
    assert said in text and text.startswith("--layer")
    assert "allowed" in text


def test_the_layer_flag() -> None:
    spec = parse_layer_flag("takes/a.csv:left.index")
    assert (spec.take, spec.group, spec.loop) == ("takes/a.csv", "left.index", True)
    spec = parse_layer_flag("C:/x/a.bvh:right:once")
    assert (spec.take, spec.group, spec.loop) == ("C:/x/a.bvh", "right", False)
    for bad in ("a.csv", "a.csv:", ":left"):
        with pytest.raises(ConfigError, match="expected TAKE:GROUP"):
            parse_layer_flag(bad)


def _show(tmp_path: Path, extra: str) -> Path:
    (tmp_path / "takes").mkdir(exist_ok=True)
    (tmp_path / "takes" / "verse.csv").write_text("t\n")
    path = tmp_path / "show.toml"
    path.write_text(f'[show]\nrig = "puppet_two_hands"\n{extra}')
    return path


def test_the_show_files_takes_and_layers_resolve_against_its_folder(tmp_path: Path) -> None:
    show = load_show(_show(tmp_path, """
[takes]
verse = "takes/verse.csv"

[[layer]]
take = "verse"
group = "left"

[[layer]]
take = "takes/verse.csv"
group = "index"
loop = false
fade_s = 1.5
"""))
    assert show.takes == {"verse": str(tmp_path / "takes" / "verse.csv")}
    first, second = show.layer
    assert (first.take, first.group, first.loop, first.fade_s) == ("verse", "left", True, 0.5)
    assert second.take == str(tmp_path / "takes" / "verse.csv")
    assert (second.loop, second.fade_s) == (False, 1.5)


@pytest.mark.parametrize(("extra", "key", "said"), [
    ('[takes]\nverse = "takes/nope.csv"\n', "takes.verse", "no such file"),
    ('[[layer]]\ntake = "chorus"\ngroup = "left"\n', "layer[0].take", "no such file"),
    ('[[layer]]\ntake = "takes/verse.csv"\ngroup = "lefty"\n', "layer[0].group",
     "unknown group 'lefty'"),
    ('[[layer]]\ntake = "takes/verse.csv"\ngroup = "left"\nfade_s = 60.0\n',
     "layer[0].fade_s", "out of range"),
    ('[[layer]]\ngroup = "left"\n', "layer[0].take", "no take named"),
    ('[[layer]]\ntake = "takes/verse.csv"\ngroup = "left"\nspeed = 2\n', "layer[0].speed",
     "unknown key"),
])
def test_a_bad_layer_or_take_names_the_show_file_and_the_key(
        tmp_path: Path, extra: str, key: str, said: str) -> None:
    path = _show(tmp_path, extra)
    with pytest.raises(ConfigError) as err:
        load_show(path)
    text = str(err.value)
    assert str(path) in text and f"'{key}'" in text and said in text, text
