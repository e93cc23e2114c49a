"""A servo missing at start-up follows ``[silence] action`` (issue 24.2).

A real ``handrig run`` against the bus emulator on a pty whose servo 7 never
answers (``missing=7``, as if unplugged). With ``action = "stop"`` the run refuses
before torque-on, naming the servo, and no goal reaches the others. With the
shipped ``action = "continue"`` the run starts without it: no goal Sync Write ever
names servo 7, the others follow the glove within their limits, the message names
it once, the summary lists it, and torque goes off at the end.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from handrig.config.paths import CONFIG_DIR
from handrig.config.rig import load_rig_config
from sim.demo_recording import DEMO_RECORDING
from sim.dxl_bus import GOAL_POSITION_ADDRESS, SimBus
from sim.dxl_faults import FaultSpec

CLI = [sys.executable, "-m", "handrig.cli"]
MISSING = 7


def test_a_servo_missing_at_start_refuses_the_run_naming_it_when_silence_action_is_stop(
        tmp_path: Path) -> None:
    text = (CONFIG_DIR / "rig.toml").read_text()
    assert 'action = "continue"' in text
    rig_file = tmp_path / "rig.toml"
    rig_file.write_text(text.replace('action = "continue"', 'action = "stop"', 1))
    rig = load_rig_config(rig_file)
    assert rig.silence.action == "stop"
    joint = rig.servo(MISSING).joint
    env = {**os.environ, "HOME": str(tmp_path), "XDG_CONFIG_HOME": str(tmp_path / "cfg"),
           "MUJOCO_GL": "egl"}
    with SimBus.from_rig(rig, faults=FaultSpec(missing=frozenset({MISSING}))) as sim:
        proc = subprocess.run(
            [*CLI, "run", "--rig", str(rig_file), "--glove", f"replay:{DEMO_RECORDING}",
             "--bus", sim.port_path, "--seconds", "5", "--json"],
            capture_output=True, text=True, env=env, timeout=120)
        servos = [sim.servo(s.id) for s in rig.servos if s.id != MISSING]
        assert not any(s.torque_enabled for s in servos)
        goals = sim.stats.goals_decoded
    assert proc.returncode != 0, proc.stdout[-2000:]
    said = proc.stdout + proc.stderr
    assert f"servo {MISSING} ({joint}) did not answer" in said, said[-2000:]
    assert goals == 0, f"{goals} goals reached the servos of a refused run"
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    assert f"servo {MISSING} ({joint})" in summary["error"]


def test_a_servo_missing_at_start_is_left_out_when_silence_action_is_continue(
        tmp_path: Path) -> None:
    rig = load_rig_config()
    assert rig.silence.action == "continue"  # the shipped policy
    joint = rig.servo(MISSING).joint
    env = {**os.environ, "HOME": str(tmp_path), "XDG_CONFIG_HOME": str(tmp_path / "cfg"),
           "MUJOCO_GL": "egl"}
    goal_ids: set[int] = set()
    goal_writes = [0]

    def seen(t_s: float, address: int, items: list[tuple[int, bytes]]) -> None:
        if address == GOAL_POSITION_ADDRESS:
            goal_writes[0] += 1
            goal_ids.update(i for i, _ in items)

    with SimBus.from_rig(rig, faults=FaultSpec(missing=frozenset({MISSING}))) as sim:
        sim.on_sync_write = seen
        proc = subprocess.run(
            [*CLI, "run", "--glove", f"replay:{DEMO_RECORDING}", "--bus", sim.port_path,
             "--seconds", "1.5", "--json"],  # 300 cycles following the glove, 1 s ease
            capture_output=True, text=True, env=env, timeout=120)
        left = sim.servo(MISSING)
        others = [sim.servo(s.id) for s in rig.servos if s.id != MISSING]
        assert not left.torque_enabled and not any(s.torque_enabled for s in others)
        outside = sim.stats.goals_outside
    said = proc.stderr
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    assert proc.returncode == 0 and "error" not in summary, (summary.get("error"), said)
    assert summary["torque_off"] is True
    assert summary["servos_left_out"] == [f"servo {MISSING} ({joint})"]
    assert said.count(f"servo {MISSING} ({joint})") == 1, said  # named once, no tiers
    assert goal_writes[0] > 100, "the others never followed the glove"
    assert MISSING not in goal_ids
    assert goal_ids == {s.id for s in rig.servos} - {MISSING}
    assert outside == 0
