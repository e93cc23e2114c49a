"""A servo that is hot: a real ``handrig run --json`` against ``handrig sim-bus`` in its
own process, the wrist servo starting at 62 C (``--faults hot=19@62``, as after a long
hold). The run warns, caps its effort and names it in the events and the summary;
with ``[heat] action = "stop"`` and the servo past action_c the run ends naming it,
torque off."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

from handrig.config.paths import CONFIG_DIR
from sim.demo_recording import DEMO_RECORDING
from tests.helpers.emulator import start_sim_bus

CLI = [sys.executable, "-m", "handrig.cli"]
WRIST = "servo 19 (riWristFlexion)"


def run(port: str, tmp_path: Path, heat_action: str) -> dict:
    rig = (CONFIG_DIR / "rig.toml").read_text()
    heat = rig.index("[heat]")
    tail, n = re.subn(r'(?m)^action = "\w+"', f'action = "{heat_action}"', rig[heat:], count=1)
    assert n == 1
    config = tmp_path / "rig.toml"
    config.write_text(rig[:heat] + tail)
    out = subprocess.run(
        [*CLI, "run", "--config", str(config), "--glove", f"replay:{DEMO_RECORDING}",
         "--bus", port, "--seconds", "2", "--json"],
        capture_output=True, text=True, timeout=120)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_hot_wrist_is_warned_and_capped_by_name_and_the_show_goes_on(tmp_path: Path) -> None:
    with start_sim_bus("--no-realtime", "--faults", "hot=19@62") as bus:
        port = bus.port
        summary = run(port, tmp_path, "relax")
    assert summary["stop_reason"] == "2 s done" and summary["torque_off"] is True
    heat = summary["heat"]
    assert (heat["warnings"], heat["reliefs"], heat["actions"]) == (1, 1, 0), heat
    assert heat["hottest"] == f"{WRIST} 62 C" and heat["max_c"][18] == 62.0
    assert max(t for i, t in enumerate(heat["max_c"]) if i != 18) < 40.0
    said = [e for e in summary["events"] if "[heat]" in e]
    assert len(said) == 2 and all(e.startswith(f"{WRIST} is at 62 C") for e in said), said
    assert "capped at 50 %" in said[1]


def test_past_action_c_with_stop_the_run_ends_naming_it_with_torque_off(
        tmp_path: Path) -> None:
    with start_sim_bus("--no-realtime", "--faults", "hot=19@66") as bus:
        port = bus.port
        summary = run(port, tmp_path, "stop")
    assert summary["stop_reason"].startswith("device error")
    # it starts at 66 C and cools as it idles: a slow start on a loaded machine reads 65 C
    hot = re.search(re.escape(WRIST) + r" is at (\d+) C \(\[heat\] action_c 65 C\)",
                    summary["stop_reason"])
    assert hot is not None and int(hot.group(1)) in (65, 66), summary["stop_reason"]
    assert "[heat] action is stop" in summary["stop_reason"]
    assert summary["torque_off"] is True
