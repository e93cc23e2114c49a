"""Configuration you can see: the files a command uses, and where each value comes from."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from handrig.cli import main
from handrig.config.paths import installed_config

ROOT = Path(__file__).resolve().parents[3]
DEMO_GLOVE = ROOT / "config" / "recordings" / "demo_glove.csv"


def env_for(home: Path, **extra: str) -> dict[str, str]:
    return {**os.environ, "XDG_CONFIG_HOME": str(home / "config"),
            "XDG_DATA_HOME": str(home / "data"), **extra}


def handrig(args: list[str], env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "handrig.cli", *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_run_on_the_sim_bus_prints_the_files_it_uses_and_why(tmp_path: Path) -> None:
    mine = tmp_path / "config" / "handrig" / "glove.toml"
    mine.parent.mkdir(parents=True)
    shutil.copyfile(installed_config("glove.toml"), mine)  # as `calibrate glove` leaves it
    res = handrig(["run", "--bus", "sim", "--glove", f"replay:{DEMO_GLOVE}", "--frames", "20"],
                  env_for(tmp_path))
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    # before anything else the run prints: that the bus is simulated, then the files
    assert lines[0].startswith("SIMULATED rig (--port sim)")
    assert lines[1] == "files in use:"
    head = "\n".join(lines[:7])
    assert f"rig           {installed_config('rig.toml')}  (shipped default" in head
    assert f"glove         {mine}  (your calibration, written by `handrig calibrate glove`)" \
        in head
    assert f"{installed_config('maps/default.toml')}  (shipped default" in head
    assert f"sag grid      {installed_config('sag_grid.npz')}  (shipped default; no baked " \
           f"grid of yours at {tmp_path / 'data' / 'handrig' / 'sag_grid.npz'})" in head


def test_one_flag_names_a_rig_in_every_command(capsys: pytest.CaptureFixture[str]) -> None:
    from handrig.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices  # type: ignore[union-attr]
    def has_rig(p: object) -> bool:
        return any("--rig" in a.option_strings for a in p._actions)  # type: ignore[attr-defined]

    for command in ("run", "demo", "sim-bus"):
        assert has_rig(sub[command]), command
    for group, names in (("calibrate", ("servos", "glove")),
                         ("servos", ("scan", "set-id", "set-baud", "reboot", "check")),
                         ("config", ("show",)), ("retarget", ("check",))):
        inner = next(a for a in sub[group]._actions if a.choices)  # type: ignore[attr-defined]
        for name in names:
            assert has_rig(inner.choices[name]), (group, name)
    # --config is the rig's old name in run: both spell the same thing
    args = parser.parse_args(["run", "--config", "leap"])
    assert args.rig == "leap"
    assert parser.parse_args(["demo", "--config", "leap"]).rig == "leap"


def test_config_show_gives_each_value_its_source(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    rig = tmp_path / "rig.toml"
    text = installed_config("rig.toml").read_text().replace("watchdog_ms = 100", "")
    text = text.replace("[calibration]\nmax_zero_shift_deg = 20.0", "")
    rig.write_text(text.replace("[bus]\n", "[bus]\n# mine\n"))
    assert main(["config", "show", "--rig", str(rig)]) == 0
    out = capsys.readouterr().out
    assert f"rig           {rig}  (--rig)" in out
    assert "bus.watchdog_ms = 100" in out
    line = next(x for x in out.splitlines() if "bus.watchdog_ms" in x)
    assert line.endswith("<- default")
    line = next(x for x in out.splitlines() if "bus.baud" in x)
    assert line.endswith("<- rig.toml")
    line = next(x for x in out.splitlines() if "calibration.max_zero_shift_deg" in x)
    assert "20.0" in line and line.endswith("<- default")
    assert "servos[19].joint = \"riWristDeviation\"" in out
    assert "channels[0].raw_open" in out  # the glove file's values too


def test_a_missing_display_or_renderer_names_the_flag_and_the_fix(tmp_path: Path) -> None:
    env = {k: v for k, v in env_for(tmp_path).items()
           if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    res = handrig(["run", "--bus", "sim", "--viewer", "--frames", "5"], env)
    assert res.returncode == 2
    assert "--viewer" in res.stderr and "needs a display" in res.stderr
    assert "handrig demo --render" in res.stderr
    import ctypes.util

    if ctypes.util.find_library("OSMesa") is not None:
        pytest.skip("OSMesa is installed here: nothing missing to report")
    res = handrig(["demo", "--frames", "5"], {**env, "MUJOCO_GL": "osmesa"})
    assert res.returncode == 2
    assert "MUJOCO_GL" in res.stderr and "OSMesa library is not installed" in res.stderr
    assert "make render-deps" in res.stderr and "glGetError" not in res.stderr
