"""User directories (handrig/paths.py), and commands that leave the checkout untouched."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from handrig.cli import main
from handrig.config import paths

CHECKOUT = Path(__file__).resolve().parents[3]


def config_status() -> str:
    """``git status`` of config/: empty when no command changed or added a file there."""
    res = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all", "config"],
                         cwd=CHECKOUT, capture_output=True, text=True, check=False)
    if res.returncode != 0:
        pytest.skip(f"not a git checkout: {res.stderr.strip()}")
    return res.stdout


@pytest.fixture
def xdg(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, Path]:
    dirs = {"config": tmp_path / "xdg-config", "data": tmp_path / "xdg-data"}
    monkeypatch.setenv("XDG_CONFIG_HOME", str(dirs["config"]))
    monkeypatch.setenv("XDG_DATA_HOME", str(dirs["data"]))
    return dirs


def test_xdg_directories_follow_the_specification(tmp_path: Path) -> None:
    env = {"HOME": str(tmp_path), "XDG_CONFIG_HOME": "/etc/xdg-mine", "XDG_DATA_HOME": ""}
    assert paths.user_config_dir(env) == Path("/etc/xdg-mine/handrig")
    assert paths.user_data_dir(env) == tmp_path / ".local/share/handrig"  # empty: ignored
    env["XDG_CONFIG_HOME"] = "relative/dir"  # not absolute: ignored
    assert paths.user_config_dir(env) == tmp_path / ".config/handrig"


def test_config_file_prefers_the_users_copy(xdg: dict[str, Path]) -> None:
    installed = paths.installed_config("glove.toml")
    assert paths.config_file("glove.toml") == installed
    assert paths.is_installed(installed) and not paths.is_installed(xdg["config"])
    assert paths.output_for(installed, "glove.toml") == xdg["config"] / "handrig/glove.toml"
    mine = paths.user_copy("glove.toml")  # copied on first use
    assert mine.read_bytes() == installed.read_bytes()
    assert paths.config_file("glove.toml") == mine
    assert paths.output_for(mine, "glove.toml") == mine
    mine.write_text("# mine\n")
    assert paths.user_copy("glove.toml").read_text() == "# mine\n"  # never overwritten


def test_bake_writes_into_the_data_directory(xdg: dict[str, Path],
                                            capsys: pytest.CaptureFixture[str]) -> None:
    before = config_status()
    assert main(["bake", "--step-deg", "30", "--plot", "--quiet"]) == 0
    grid = xdg["data"] / "handrig" / "sag_grid.npz"
    assert grid.exists() and grid.with_suffix(".png").exists()
    out = capsys.readouterr().out
    assert f"wrote {grid}" in out and "read it from now on (your baked grid)" in out
    assert config_status() == before


def test_help_says_where_files_go(capsys: pytest.CaptureFixture[str]) -> None:
    for argv in (["bake"], ["calibrate", "glove"], ["calibrate", "servos"]):
        assert main([*argv, "--help"]) == 0
        text = " ".join(capsys.readouterr().out.split())
        assert "XDG_" in text and "never rewritten" in text, argv


def test_demo_recording_script_writes_into_the_data_directory(tmp_path: Path) -> None:
    import os
    import sys

    before = config_status()
    env = {**os.environ, "XDG_DATA_HOME": str(tmp_path / "data")}
    res = subprocess.run([sys.executable, "-m", "sim.demo_recording", "--rate", "50"],
                         cwd=CHECKOUT, env=env, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    out = tmp_path / "data" / "handrig" / "recordings" / "demo_glove.csv"
    assert res.stdout.startswith(f"wrote {out}") and out.exists()
    assert config_status() == before


def test_passive_tune_writes_the_users_copy_which_bake_then_reads(
        xdg: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    before = config_status()
    assert main(["passive", "tune"]) == 0
    mine = xdg["config"] / "handrig" / "passive_hand.toml"
    assert f"wrote {mine}" in capsys.readouterr().out and mine.exists()
    assert paths.config_file("passive_hand.toml") == mine
    assert config_status() == before
