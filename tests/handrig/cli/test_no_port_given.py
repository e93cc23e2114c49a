"""Nothing touches a simulated bus unless asked (issue 37): the shipped rig names no
port, and a command without one stops, before any device or emulator, naming
``--port PORT`` and ``--port sim``. No emulator runs here: compute_only."""

from __future__ import annotations

from pathlib import Path

import pytest

from handrig.cli import main
from handrig.config.paths import installed_config
from handrig.config.rig import load_rig_config

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
