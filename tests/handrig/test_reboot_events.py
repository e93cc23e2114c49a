"""Reboots and hardware errors are events of the run (``--json`` included), said
once: a real ``handrig run`` against ``handrig sim-bus --faults overload=3@1.5``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from sim.demo_recording import DEMO_RECORDING

CLI = [sys.executable, "-m", "handrig.cli"]


def test_a_hardware_error_and_its_reboot_are_events_in_json(tmp_path: Path) -> None:
    sim = subprocess.Popen([*CLI, "sim-bus", "--no-realtime", "--faults", "overload=3@4"],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                           start_new_session=True)
    try:
        assert sim.stdout is not None
        port = sim.stdout.readline().split()[1]
        err = tmp_path / "stderr.txt"
        with open(err, "w") as f:
            run = subprocess.run(
                [*CLI, "run", "--glove", f"replay:{DEMO_RECORDING}", "--bus", port,
                 "--seconds", "6", "--json"], stdout=subprocess.PIPE, stderr=f, text=True,
                timeout=180)
    finally:
        sim.terminate()
        try:
            sim.wait(timeout=10)
        except subprocess.TimeoutExpired:
            sim.kill()
            sim.wait()
    summary = json.loads(run.stdout.strip().splitlines()[-1])
    events = summary["events"]
    assert summary["bus"]["reboots"] >= 1, summary["bus"]
    hw = [e for e in events if "servo 3 (riThumbCMCz) hardware error" in e]
    assert hw and "rebooting it" in hw[0], events
    back = [e for e in events if "servo 3 (riThumbCMCz) rebooted" in e]
    assert back, events
    text = err.read_text()
    assert text.count(hw[0]) == 1, text  # said once
