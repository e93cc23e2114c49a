"""``python -m bench soak``, short: the live rig with bus, host and glove faults and
recording on ends with torque off, no goal outside the limits, and its figures."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_a_short_soak_prints_its_figures_with_no_goal_outside_the_limits() -> None:
    # 8 s (1600 cycles at 200 Hz, VMC at 60 Hz), a stall every 2 s; servo 4 muted from the
    # emulator's 5.5 s to 7.5 s: inside the run whether it starts 0.4 s (a quiet machine)
    # or 4.6 s (CI, beside the compute-only tests) after the emulator; a servo silent at
    # the start rightly stops the run before torque
    out = subprocess.run(
        [sys.executable, "-m", "bench", "soak", "--seconds", "8", "--stall-every-s", "2",
         "--mute", "4@5.5-7.5"],
        capture_output=True, text=True, timeout=240, cwd=ROOT)
    text = out.stdout
    assert out.returncode == 0, out.stderr[-2000:]
    cycles = re.search(r"cycles\s+(\d+) in", text)
    assert cycles and int(cycles.group(1)) > 700, text
    assert re.search(r"goals outside\s+0 of [1-9]\d* decoded", text), text
    assert re.search(r"a 50 ms host stall every 2 s \([2-4] made\)", text), text
    assert "bus injected    " in text and "(no count" not in text, text
    assert re.search(r"rss\s+[\d.]+ MB at the start, [\d.]+ MB at the end; growth", text), text
    assert re.search(r"stopped\s+8 s done\n", text), text
    assert "torque off      True" in text, text
    # VMC on: the bundles reached a real UDP socket
    vmc = re.search(r"vmc\s+(\d+) datagrams", text)
    assert vmc and int(vmc.group(1)) > 330, text
    # the hottest reading per servo, as the driver read it
    assert re.search(r"temperature\s+max \d+ C at servo \d+ \w+ X[LCM]\d+", text), text
    # the muted servo was held while it was silent, and answered again
    assert re.search(r"held\s+servo 4 riThumbMCPz XL330-M288: \d+ times, [1-3]\.\d+ s", text), text
    assert "muted replies" in text, text


def test_the_soak_is_not_part_of_a_plain_bench_run() -> None:
    from bench.__main__ import LONG

    assert "bench_soak" in LONG
