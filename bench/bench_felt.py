"""Felt latency of ``handrig run`` from outside, and that process's CPU: ``python -m bench felt``.

The rig runs as a user starts it: ``handrig run`` in a process of its own (the
shipped rig at 1 Mbps, glove-triggered loop, the glove's One Euro filter off so a
step moves the goals in the very next write), between the two emulators of
:mod:`bench.latency_emulators`, each in its own process: a glove at 200 Hz
streaming a recording whose index channel steps every 0.25 s, and 20 emulated
servos with wire timing that log each Sync Write's receipt. It prints:

* felt latency: the glove emulator's send time of a frame carrying a step to the
  bus emulator's receipt of the first Sync Write whose goals moved (both
  CLOCK_MONOTONIC), p50 / p90 / p99 in microseconds;
* the ``handrig run`` process's CPU over its steady part, in % of one core (all its
  threads: utime + stime from ``/proc/PID/stat``, sampled from outside 1 s after
  the first goal reached the bus and again before the run ends);
* the run's own figures (``--json``): in-process latency p50 / p99, read timeouts,
  stale readings.

``HANDRIG_BENCH_SECONDS`` (default 15) sets the steady part; ``HANDRIG_BENCH_ROUNDS``
(default 2) the rounds; ``HANDRIG_BENCH_TREES``: checkouts whose ``handrig`` is run,
alternated in each round (colon-separated; default this one), to compare old and
new side by side in one run; ``HANDRIG_BENCH_POLL_US``: ``[loop] glove_poll_us`` values
(comma-separated; default the rig's own), each alternated too (trees that know the key);
``HANDRIG_BENCH_WARM_UP_US`` the same for ``[loop] warm_up_us``, ``HANDRIG_BENCH_AWAKE``
(``false,true``) for ``[loop] keep_cpus_awake``. The CPUs' idle polling (the kernel's
POLL idle state, from ``/sys/devices/system/cpu/cpu*/cpuidle/state0/time``: what keeping
them awake costs, in power, not in any process's CPU) is printed as a share of all CPUs'
time over the same steady part::

    git worktree add /tmp/base 22013e1
    HANDRIG_BENCH_TREES=/tmp/base:. python -m bench felt
    HANDRIG_BENCH_POLL_US=0,150 python -m bench felt
    HANDRIG_BENCH_WARM_UP_US=150,300 python -m bench felt
    HANDRIG_BENCH_AWAKE=false,true python -m bench felt
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
from typing import Any

import numpy as np

from bench.bench_rig import _rig_file
from bench.rig_steps import (
    INDEX_CHANNEL,
    ROOT,
    _glove_file,
    emulator,
    outside_latencies,
    step_recording,
)
from handrig.devices.glove_recording import write_glove_recording

GLOVE_HZ = 200.0
BAUD = 1_000_000
WARM_S = 1.0  # after the first goal reaches the bus: start-up's CPU left out
TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")


def process_cpu_s(pid: int) -> float:
    """utime + stime of process ``pid`` (all its threads), seconds."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) * TICK_S  # fields 14 and 15 of stat(5)


def _wait_for_lines(path: Path, proc: subprocess.Popen[str], timeout_s: float) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if proc.poll() is not None:
            raise RuntimeError(f"handrig run ended early:\n{proc.communicate()[0][-2000:]}")
        if path.exists() and path.stat().st_size > 0:
            return
        time.sleep(0.05)
    raise RuntimeError(f"no goal reached the bus emulator in {timeout_s:.0f} s")


def idle_poll_s() -> float:
    """Seconds all CPUs spent in the kernel's POLL idle state (0 where not reported)."""
    total = 0
    for f in Path("/sys/devices/system/cpu").glob("cpu[0-9]*/cpuidle/state0/time"):
        try:
            if f.with_name("name").read_text().strip() == "POLL":
                total += int(f.read_text())
        except (OSError, ValueError):
            continue
    return total * 1e-6


def _loop_key(rig_path: Path, key: str, value: float | str, out: Path) -> Path:
    """``rig_path`` with ``[loop] key = value``, written to ``out``."""
    text = re.sub(rf"(?m)^{key} = .*$", "", rig_path.read_text(encoding="utf-8"))
    shown = f"{value:g}" if isinstance(value, float) else value
    out.write_text(text.replace("[loop]\n", f"[loop]\n{key} = {shown}\n", 1),
                   encoding="utf-8")
    return out


def run_once(tree: Path, seconds: float, folder: Path, tag: str,
             poll_us: float | None = None, warm_up_us: float | None = None,
             awake: str | None = None) -> dict[str, Any]:
    rec = step_recording()
    rec_path = folder / "steps.csv"
    write_glove_recording(rec_path, rec)
    # the tree's own rig file: an older tree may not know a newer key
    rig_path = _rig_file(folder, "glove", GLOVE_HZ, BAUD, tree / "config" / "rig.toml")
    if poll_us is not None:
        rig_path = _loop_key(rig_path, "glove_poll_us", poll_us, folder / f"rig_poll_{tag}.toml")
    if warm_up_us is not None:
        rig_path = _loop_key(rig_path, "warm_up_us", warm_up_us, folder / f"rig_warm_{tag}.toml")
    if awake is not None:
        rig_path = _loop_key(rig_path, "keep_cpus_awake", awake, folder / f"rig_awake_{tag}.toml")
    glove_log, bus_log = folder / f"glove_{tag}.log", folder / f"bus_{tag}.log"
    env = dict(os.environ, PYTHONPATH=str(tree))
    with (emulator(["bus", "--rig", str(rig_path), "--log", str(bus_log)],
                   "the bus emulator") as bus_port,
          emulator(["glove", str(rec_path), "--rate", f"{GLOVE_HZ:g}",
                    "--log", str(glove_log)], "the glove emulator") as glove_port):
        argv = [sys.executable, "-m", "handrig.cli", "run", "--rig", str(rig_path),
                "--glove-config", str(_glove_file(folder)), "--glove", glove_port,
                "--bus", bus_port, "--seconds", f"{seconds + WARM_S + 2.0:g}", "--json"]
        proc = subprocess.Popen(argv, cwd=tree, env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)
        try:
            _wait_for_lines(bus_log, proc, 60.0)
            time.sleep(WARM_S)
            t0, c0, p0 = time.monotonic(), process_cpu_s(proc.pid), idle_poll_s()
            time.sleep(seconds)
            t1, c1, p1 = time.monotonic(), process_cpu_s(proc.pid), idle_poll_s()
            out, _ = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    summary = json.loads(out[out.index("{"):]) if "{" in out else {}
    sends = [(float(a), int(c)) for a, _, c in
             (line.split() for line in glove_log.read_text().splitlines() if line)]
    writes = [(float(f[0]), tuple(int(v) for v in f[1:]))
              for f in (line.split() for line in bus_log.read_text().splitlines()) if f]
    lat = np.array(outside_latencies(sends, rec.raw[:, INDEX_CHANNEL].copy(), writes)) * 1e6
    inside = summary.get("latency_us", {})
    bus = summary.get("bus", {})
    return {
        "tree": str(tree), "n": len(lat),
        "p50": float(np.percentile(lat, 50)) if len(lat) else None,
        "p90": float(np.percentile(lat, 90)) if len(lat) else None,
        "p99": float(np.percentile(lat, 99)) if len(lat) else None,
        "cpu_pct": 100.0 * (c1 - c0) / (t1 - t0),
        "idle_poll_pct": 100.0 * (p1 - p0) / ((t1 - t0) * (os.cpu_count() or 1)),
        "inside_p50": inside.get("p50"), "inside_p99": inside.get("p99"),
        "timeouts": bus.get("timeouts"), "stale": bus.get("stale_readings"),
        "delayed": summary.get("writes_delayed_by_reads"),
    }


def _fmt(v: float | None, digits: int = 0) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def main() -> None:
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", "15"))
    rounds = int(os.environ.get("HANDRIG_BENCH_ROUNDS", "2"))
    trees = [Path(t).resolve() for t in
             os.environ.get("HANDRIG_BENCH_TREES", str(ROOT)).split(":") if t]
    polls: list[float | None] = [float(v) for v in
                                 os.environ.get("HANDRIG_BENCH_POLL_US", "").split(",") if v]
    warm_ups: list[float | None] = [float(v) for v in
                                    os.environ.get("HANDRIG_BENCH_WARM_UP_US", "").split(",") if v]
    awakes: list[str | None] = [v.strip() for v in
                                os.environ.get("HANDRIG_BENCH_AWAKE", "").split(",") if v]
    variants = [(tree, poll, warm, awake) for tree in trees for poll in (polls or [None])
                for warm in (warm_ups or [None]) for awake in (awakes or [None])]
    print(f"handrig run from outside: glove {GLOVE_HZ:g} Hz, {BAUD} bps, 20 servos, "
          f"{seconds:g} s steady x {rounds} rounds (load {os.getloadavg()[0]:.1f})")
    print("| tree | glove_poll_us | warm_up_us | keep_cpus_awake | round | "
          "felt p50 / p90 / p99 (us), steps | CPU (% of a core) | CPUs idle polling (%) | "
          "in process p50 / p99 (us) | writes delayed by reads | read timeouts | "
          "stale readings | load |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory(prefix="bench_felt_") as tmp:
        for r in range(rounds):
            for k, (tree, poll, warm, awake) in enumerate(variants):
                res = run_once(tree, seconds, Path(tmp), f"{r}_{k}", poll, warm, awake)
                label = "rig's" if poll is None else f"{poll:g}"
                warm_label = "rig's" if warm is None else f"{warm:g}"
                awake_label = "rig's" if awake is None else awake
                print(f"| {tree} | {label} | {warm_label} | {awake_label} | "
                      f"{r + 1} | {_fmt(res['p50'])} / "
                      f"{_fmt(res['p90'])} / "
                      f"{_fmt(res['p99'])}, {res['n']} | {res['cpu_pct']:.1f} | "
                      f"{res['idle_poll_pct']:.1f} | "
                      f"{_fmt(res['inside_p50'])} / {_fmt(res['inside_p99'])} | "
                      f"{res['delayed']} | {res['timeouts']} | {res['stale']} | "
                      f"{os.getloadavg()[0]:.1f} |",
                      flush=True)


if __name__ == "__main__":
    main()
