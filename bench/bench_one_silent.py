"""One servo silenced in a real run: how many other servos the run names as silent.

A real ``handrig run`` (the demo recording, ``[silence] action = "continue"``) against
``handrig sim-bus --no-puppet`` in its own process; ``HANDRIG_BENCH_SECONDS`` (default
8) after the servos are commissioned plus 1 s, servo 7 gets Status Return Level 0
through a Sync Write of its own. Printed: the servo warnings naming servo 7, those
naming others, every line about servos going quiet or answering again, and the run's
events. Say the machine's load when quoting it: an emulator starved of CPU misses
whole reads. ``python -m bench.compare --base COMMIT --benches one_silent``.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from firmware_protocol import dynamixel as dx
from handrig.config.paths import CONFIG_DIR
from sim.demo_recording import DEMO_RECORDING

CLI = [sys.executable, "-m", "handrig.cli"]
SILENT = "servo 7 (riIndexMCPy)"


def _run(seconds: float) -> dict:
    sim = subprocess.Popen([*CLI, "sim-bus", "--no-realtime", "--no-puppet"],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                           start_new_session=True)
    try:
        assert sim.stdout is not None
        port = sim.stdout.readline().split()[1]
        with tempfile.TemporaryDirectory() as tmp:
            rig = re.sub(r'(?m)^action = "\w+"', 'action = "continue"',
                         (CONFIG_DIR / "rig.toml").read_text(), count=1)
            config = Path(tmp) / "rig.toml"
            config.write_text(rig)
            err = Path(tmp) / "stderr.txt"
            with open(err, "w") as f:
                run = subprocess.Popen(
                    [*CLI, "run", "--config", str(config), "--glove",
                     f"replay:{DEMO_RECORDING}", "--bus", port, "--seconds",
                     f"{seconds + 1.5:g}", "--json"],
                    stdout=subprocess.PIPE, stderr=f, text=True)
            deadline = time.monotonic() + 120
            while "commissioned" not in err.read_text() and time.monotonic() < deadline:
                time.sleep(0.05)
            time.sleep(1.0)
            fd = os.open(port, os.O_RDWR | os.O_NOCTTY)
            try:
                os.write(fd, dx.build_instruction(
                    dx.BROADCAST_ID, dx.Instruction.SYNC_WRITE,
                    dx.sync_write_params(dx.Reg.STATUS_RETURN_LEVEL, 1, [(7, bytes([0]))])))
            finally:
                os.close(fd)
            out, _ = run.communicate(timeout=300)
            return json.loads(out.strip().splitlines()[-1])
    finally:
        sim.terminate()
        sim.wait(timeout=10)


def main() -> None:
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", "8"))
    summary = _run(seconds)
    events = summary["events"]
    warnings = [e for e in events if e.startswith("no valid reply from")]
    others = [e for e in warnings if set(re.findall(r"servo \d+ \(\w+\)", e.split(" for ")[0]))
              - {SILENT}]
    quiet = [e for e in events if "no valid reply" in e or "answer again" in e
             or "unanswered as a whole" in e or "answers again" in e]
    print(f"servo 7 silenced for about {seconds:g} s of a real run "
          f"(load {os.getloadavg()[0]:.1f}):")
    print(f"  warnings naming servo 7        {sum(SILENT in e for e in warnings)}")
    print(f"  warnings naming other servos   {len(others)}")
    print(f"  lines about quiet or answering {len(quiet)}")
    print(f"  events in the run              {summary.get('events_total', len(events))}")
    if os.environ.get("HANDRIG_BENCH_VERBOSE"):
        for e in quiet:
            print(f"    {e[:160]}")


if __name__ == "__main__":
    main()
