"""``handrig retarget fit`` and the figures ``retarget check`` gives through the model."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from handrig.cli import main
from handrig.config.loading import CONFIG_DIR
from handrig.pose.retarget import load_retarget


def test_check_json_reports_fist_pinch_and_tip_error(capsys: pytest.CaptureFixture[str]) -> None:
    status = main(["retarget", "check", "--rig", "orca", "--no-capture", "--json"])
    out = json.loads(capsys.readouterr().out)
    # exit 1 exactly when a joint is flagged (the demo reaches past the robot's range)
    assert status == (1 if any({"demo", "capture"} & set(j["flags"])
                               for j in out["joints"]) else 0)
    assert set(out["fist_closure"]) == {"index", "middle", "ring", "pinky"}
    assert set(out["pinch_gap_mm"]) == {"thumb_index", "thumb_middle"}
    assert len(out["joints"]) == 17  # the joint checks are still there
    assert out["tip_error_mm"] == {}  # without the capture there is no error to give
    status = main(["retarget", "check", "--rig", "leap", "--no-capture", "--no-model",
                   "--json"])
    out = json.loads(capsys.readouterr().out)
    assert "fist_closure" not in out
    assert status == (1 if any({"demo", "capture"} & set(j["flags"])
                               for j in out["joints"]) else 0)


def test_check_prints_the_grasp_figures(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["retarget", "check", "--rig", "leap"]) in (0, 1)  # 1: a joint flagged
    out = capsys.readouterr().out
    assert "through the robot's model" in out
    assert "fist closure index" in out and "pinch gap thumb_index" in out
    assert "fingertip error over the capture: median" in out


def test_fit_writes_only_where_told(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    shipped = CONFIG_DIR / "rigs" / "leap_retarget.toml"
    text = shipped.read_text()
    out = tmp_path / "leap_fit.toml"
    assert main(["retarget", "fit", "--rig", "leap", "--out", str(out),
                 "--max-evaluations", "1", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["written"] == str(out) and "fist_closure" in res["before"]
    assert shipped.read_text() == text  # the shipped table is untouched
    fitted = load_retarget(out)
    assert fitted.joint_names == load_retarget(shipped).joint_names
    assert "handrig retarget fit --rig leap" in out.read_text()
    dry = tmp_path / "not_written.toml"
    assert main(["retarget", "fit", "--rig", "leap", "--out", str(dry), "--dry-run",
                 "--max-evaluations", "1"]) == 0
    assert not dry.exists() and "nothing written" in capsys.readouterr().out
    assert main(["retarget", "fit", "--rig", str(CONFIG_DIR / "rig.toml")]) == 2
    assert "not a robot rig" in capsys.readouterr().err


def test_check_renders_the_robot_at_the_human_grasps(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import os
    import subprocess
    import sys

    out = tmp_path / "grasps.png"
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    run = subprocess.run(
        [sys.executable, "-m", "handrig.cli", "retarget", "check", "--rig", "orca",
         "--no-capture", "--no-model", "--render", str(out), "--view", "0.3,0,-20"],
        capture_output=True, text=True, timeout=300, env=env)
    if run.returncode not in (0, 1) and "render" in run.stderr.lower() and not out.exists():
        pytest.skip(run.stderr.strip().splitlines()[-1])
    assert run.returncode in (0, 1), run.stderr[-2000:]  # 1: a joint flagged by the check
    from matplotlib.image import imread

    # open hand, fist and two pinches: four tiles in rows of three
    assert imread(out).shape[:2] == (2 * 240, 3 * 320)
    table = tmp_path / "t.toml"
    table.write_text(load_retarget(CONFIG_DIR / "rigs" / "leap_retarget.toml") and
                     (CONFIG_DIR / "rigs" / "leap_retarget.toml").read_text())
    assert main(["retarget", "check", "--table", str(table), "--no-capture",
                 "--render", str(tmp_path / "no.png")]) == 2
    assert "--render draws the rig's robot model" in capsys.readouterr().err
