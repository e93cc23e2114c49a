"""Issue 37's messages, none needing a device (compute_only): nothing touches a
simulated bus unless asked (the shipped rig names no port; a command without one stops
naming ``--port PORT`` and ``--port sim``; a robot preset without one asks for it;
``setup`` refuses the simulated port); ``run --show`` says the files came from the
show; a rig with sag off lists no sag grid; an argument's error names it without a
file."""

from __future__ import annotations

from pathlib import Path

import pytest

from handrig.app.robot_api import RobotHand
from handrig.app.sources import run_sources
from handrig.cli import main
from handrig.config.paths import installed_config
from handrig.config.rig import load_rig_config
from handrig.config.show import load_show
from handrig.errors import ConfigError

ROOT = Path(__file__).resolve().parents[3]
DEMO_GLOVE = ROOT / "config" / "recordings" / "demo_glove.csv"


def test_the_shipped_rigs_name_no_port_and_commands_ask_for_one(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert load_rig_config(installed_config("rig.toml")).bus.port == ""
    for argv in (["run", "--glove", f"replay:{DEMO_GLOVE}", "--frames", "5"],
                 ["servos", "reboot", "7"], ["calibrate", "servos", "--yes"],
                 ["run", "--rig", "leap", "--glove", f"replay:{DEMO_GLOVE}"]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert "no servo port given" in err and "--port PORT" in err, (argv, err)
        assert "--port sim for the simulated rig" in err, err
    # the left bus of a rig on two buses is asked for by its own flag
    assert main(["run", "--rig", "puppet_two_buses", "--glove", f"replay:{DEMO_GLOVE}",
                 "--glove-left", f"replay:{DEMO_GLOVE}", "--port", "sim"]) == 2
    assert "--bus-left: no servo port given" in capsys.readouterr().err


def test_a_robot_preset_without_a_port_asks_for_one() -> None:
    with pytest.raises(ConfigError, match=r"no servo port.*port=\"sim\""):
        RobotHand("leap")


def test_setup_refuses_the_simulated_port(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["setup", "--port", "sim", "--no-servos"]) == 2
    err = capsys.readouterr().err
    assert "--port 'sim'" in err and "setup writes your rig file" in err


def test_run_show_says_the_rig_and_files_came_from_the_show() -> None:
    from handrig.cli.run import _show_sources

    show = load_show(ROOT / "examples" / "show.toml")
    sources = _show_sources(run_sources(show.show.rig), show, ["rig"])
    rig = next(s for s in sources if s.role == "rig")
    assert rig.why == f"the show's, {show.path}" and "--rig" not in rig.why
    # a rig given with --rig (not filled from the show) keeps its own reason
    given = _show_sources(run_sources(show.show.rig), show, [])
    assert next(s for s in given if s.role == "rig").why.endswith("--rig")


def test_a_rig_with_sag_off_lists_no_sag_grid() -> None:
    assert "sag grid" not in [s.role for s in run_sources("leap")]  # [robot] sag = false
    assert "sag grid" in [s.role for s in run_sources(None)]


def test_an_argument_is_named_without_a_file() -> None:
    assert str(ConfigError("exists", key="OUT", value="a.csv")) == "OUT = 'a.csv': exists"
    assert str(ConfigError("bad", key="--port", value="x")) == "--port 'x': bad"
    assert str(ConfigError("bad", file="r.toml", key="k", value=1)) == "r.toml: key 'k' = 1: bad"
