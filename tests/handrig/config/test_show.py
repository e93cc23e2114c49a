"""Show files: loaded and checked (errors name the file and the key), and a show
started by ``handrig run --show``, the panel and the summary naming it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from handrig.cli import main
from handrig.config.loading import CONFIG_DIR
from handrig.config.show import load_show
from handrig.errors import ConfigError

EXAMPLE = CONFIG_DIR.parent / "examples" / "show.toml"
DEMO = CONFIG_DIR / "recordings" / "demo_glove.csv"


def test_the_example_show_loads_with_its_paths_resolved():
    show = load_show(EXAMPLE)
    assert show.title == "two-hand puppet rehearsal"
    assert show.show.rig == "puppet_two_hands"
    assert show.gloves.right == f"replay:{DEMO}" and show.gloves.left == f"replay:{DEMO}"
    assert show.buses.right == "sim" and show.outputs.record == ""


@pytest.mark.parametrize(("text", "key", "says"), [
    ('[show]\nrig = "puppet_two_hands"\nrigg = "x"\n', "show.rigg", "unknown key"),
    ('[gloves]\nright = "/dev/ttyACM0"\n', "show.rig", "no rig named"),
    ('[show]\nrig = "rigs/none.toml"\n', "show.rig", "no such file"),
    ('[show]\nrig = "puppet_two_hands"\nmap = "nomap.toml"\n', "show.map", "no such file"),
    ('[show]\nrig = "puppet_two_hands"\n[gloves]\nright = "/dev/ttyACM0"\n'
     'left = "/dev/ttyACM0"\n', "gloves.left", "same port"),
    ('[show]\nrig = "puppet_two_hands"\n[outputs]\nrecord = "take.mp4"\n', "outputs.record",
     "suffix"),
    ('[show]\nrig = "puppet_two_hands"\n[outputs]\nvmc = "localhost"\n', "outputs.vmc",
     "no port"),
    ('[show]\nrig = "puppet_two_hands"\n[gloves]\nright = "replay:take.csv"\n',
     "gloves.right", "no such file"),
])
def test_a_bad_show_file_is_refused_naming_the_file_and_the_key(tmp_path, text, key, says):
    path = tmp_path / "show.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_show(path)
    message = str(err.value)
    assert str(path) in message and key in message and says in message, message


def test_a_missing_show_file_names_the_flag(tmp_path, capsys):
    assert main(["run", "--show", str(tmp_path / "none.toml")]) == 2
    err = capsys.readouterr().err
    assert "--show" in err and "none.toml" in err and "Traceback" not in err


def test_run_show_starts_the_show_it_names(tmp_path, capsys):
    show = tmp_path / "show.toml"
    take = tmp_path / "take.csv"
    show.write_text(f'[show]\nname = "rehearsal 3"\nrig = "{CONFIG_DIR}/rig.toml"\n'
                    f'[gloves]\nright = "replay:{DEMO}"\n[buses]\nright = "sim"\n'
                    f'[outputs]\nrecord = "take.csv"\n')
    status = main(["run", "--show", str(show), "--frames", "100", "--json"])
    out = capsys.readouterr().out
    summary = json.loads(out)
    assert status == 0, summary.get("error")
    assert summary["show"] == "rehearsal 3" and summary["torque_off"] is True
    assert summary["frames"] >= 100
    # the show's output, relative to the show file: recorded there
    assert summary["outputs"]["recording"]["path"] == str(take) and Path(take).is_file()
