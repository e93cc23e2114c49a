"""Gravity compensation live: the LEAP preset's loop through the real driver into
``handrig sim-bus`` (emulated XC330-M288s at Goal Current 350 on the LEAP model, under
gravity), once with ``[robot] gravity = false`` and once with ``true``: the fingers rest
short of their goals without it, at them with it."""

from __future__ import annotations

import math
import re
import time
from pathlib import Path

import numpy as np
import pytest

from handrig.app.robot_api import RobotHand
from handrig.config.rig_files import RIGS_DIR

pytest.importorskip("mujoco")
# index, middle and ring flexed at their MCP and PIP: goals mid-range, no contact
POSE = {"riIndexMCPy": 40.0, "riMiddleMCPy": 40.0, "riRingMCPy": 40.0,
        "riIndexPIPy": 30.0, "riMiddlePIPy": 30.0, "riRingPIPy": 30.0}
STILL_DEG = 0.02  # a reading that moved less than this over STILL_S has settled
STILL_S = 0.15


def _rig_file(tmp_path: Path, gravity: bool) -> Path:
    text = (RIGS_DIR / "leap.toml").read_text()
    model = (RIGS_DIR / "../../data/robots/leap_hand/right_hand.xml").resolve()
    text = re.sub(r'^model = ".*"$', f'model = "{model}"', text, count=1, flags=re.M)
    text = re.sub(r'^retarget = ".*"$', f'retarget = "{RIGS_DIR / "leap_retarget.toml"}"',
                  text, flags=re.M)
    text, n = re.subn(r"^gravity = .*$", f"gravity = {str(gravity).lower()}", text,
                      flags=re.M)
    assert n == 1
    path = tmp_path / f"leap_gravity_{gravity}.toml"
    path.write_text(text)
    return path


def _settled_error(rig_file: Path, close_deg: float | None = None) -> dict[str, float]:
    """Goal minus present angle of each joint once the readings stop moving (and, with
    ``close_deg``, every MCP is that close to its goal). On a busy machine the emulated
    physics runs slower than the wall clock and a finger still creeping toward its goal
    can look still for STILL_S: ``close_deg`` keeps waiting (up to the deadline) for the
    rest the compensated hand should reach, and the caller's assertion says if it never
    came."""
    mcps = ("if_mcp", "mf_mcp", "rf_mcp")
    with RobotHand(str(rig_file), port="sim") as robot:
        robot.move_to(POSE, seconds=0.1)
        names = robot.joint_names
        last = np.full(len(names), math.nan)
        since = time.monotonic()
        deadline = since + 10.0
        while time.monotonic() < deadline:
            present = robot.present_deg()
            now = np.array([present[n] for n in names])
            goals = robot.goals_deg()
            close = close_deg is None or max(
                abs(goals[j] - present[j]) for j in mcps) < close_deg
            if not np.all(np.abs(now - last) < STILL_DEG):
                last, since = now, time.monotonic()
            elif close and time.monotonic() - since >= STILL_S:
                break
            time.sleep(0.02)
        goals = robot.goals_deg()
        present = robot.present_deg()
    return {n: goals[n] - present[n] for n in names}


def test_compensation_brings_the_fingers_to_their_goals(tmp_path: Path) -> None:
    off = _settled_error(_rig_file(tmp_path, False))
    on = _settled_error(_rig_file(tmp_path, True), close_deg=0.2)
    mcps = ("if_mcp", "mf_mcp", "rf_mcp")
    assert min(abs(off[j]) for j in mcps) > 0.5, off  # sagging under their own weight
    assert max(abs(on[j]) for j in mcps) < 0.2, on
    rms_off = math.sqrt(np.mean([v * v for v in off.values()]))
    rms_on = math.sqrt(np.mean([v * v for v in on.values()]))
    assert rms_on < rms_off / 4, (rms_off, rms_on)
