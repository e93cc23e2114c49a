"""A servo missing at start-up under ``[silence] action = "stop"`` (issue 24.2).

A real ``handrig run`` against the bus emulator on a pty with every servo of the
shipped rig but one: the run refuses before torque-on, naming the missing servo,
and no goal ever reaches the servos that are there.

(The ``action = "continue"`` half of the issue, starting without the servo, is not
built yet: today every action refuses the same way.)
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
from sim.dxl_bus import SimBus

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
    with SimBus.from_rig(rig, ids=[s.id for s in rig.servos if s.id != MISSING]) as sim:
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
