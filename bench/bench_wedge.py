"""A wedged adapter: the time from the stall to the rig's exit, measured from outside.

A real ``handrig run`` (the demo recording replayed into the shipped rig) drives a
``handrig sim-bus`` process on a pty; once the servos follow the glove, the emulator
is stopped with SIGSTOP, as a wedged USB adapter stops draining. The figure is the
time from the SIGSTOP to the rig's process being gone (its exit status collected),
over ``--runs`` runs: the stall alone, and with a SIGTERM sent 0.2 s into it. The
issue's target is under a second. Prints each run, the median and the worst, the
message the run ended with, the load average and the CPU steal over the bench.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

from sim.demo_recording import DEMO_RECORDING

CLI = [sys.executable, "-m", "handrig.cli"]
SIGTERM_AFTER_S = 0.2


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m bench wedge", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--runs", type=int, default=5, help="runs of each case (default 5)")
    args = p.parse_args(argv)
    if args.runs < 1:
        p.error("--runs must be at least 1")
    return args


def _steal_jiffies() -> tuple[int, int]:
    """(steal, total) jiffies of all CPUs from /proc/stat."""
    with open("/proc/stat") as f:
        fields = [int(v) for v in f.readline().split()[1:]]
    return fields[7] if len(fields) > 7 else 0, sum(fields)


def one_run(sigterm: bool, workdir: Path) -> tuple[float, dict[str, object]]:
    """Seconds from the SIGSTOP to the rig's exit, and its --json summary."""
    sim = subprocess.Popen([*CLI, "sim-bus", "--no-realtime"], stdout=subprocess.PIPE,
                           stderr=subprocess.DEVNULL, text=True, start_new_session=True)
    rig: subprocess.Popen[str] | None = None
    try:
        assert sim.stdout is not None
        port = sim.stdout.readline().split()[1]
        err = workdir / "stderr.txt"
        with open(err, "w") as f:
            rig = subprocess.Popen(
                [*CLI, "run", "--glove", f"replay:{DEMO_RECORDING}", "--bus", port,
                 "--seconds", "120", "--json"],
                stdout=subprocess.PIPE, stderr=f, text=True, start_new_session=True)
        deadline = time.monotonic() + 120
        while "commissioned" not in err.read_text():
            if rig.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"the rig did not start: {err.read_text()[-2000:]}")
            time.sleep(0.05)
        time.sleep(1.5)  # torque on, goals flowing
        os.kill(sim.pid, signal.SIGSTOP)
        stalled = time.monotonic()
        if sigterm:
            time.sleep(SIGTERM_AFTER_S)
            os.kill(rig.pid, signal.SIGTERM)
        rig.wait(timeout=60)
        took = time.monotonic() - stalled
        assert rig.stdout is not None
        return took, json.loads(rig.stdout.read().strip().splitlines()[-1])
    finally:
        for proc in (rig, sim):
            if proc is not None and proc.poll() is None:
                os.kill(proc.pid, signal.SIGCONT)
                proc.kill()
                proc.wait()
        if sim.poll() is None:
            sim.kill()
        sim.wait()


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(argv if argv is not None else sys.argv[1:])
    steal0, total0 = _steal_jiffies()
    print(f"stall -> exit of a real handrig run, {args.runs} runs per case "
          "(SIGSTOP of the emulator -> the rig's process gone):")
    with tempfile.TemporaryDirectory() as tmp:
        for sigterm in (False, True):
            case = (f"stall + SIGTERM after {SIGTERM_AFTER_S:g} s" if sigterm
                    else "stall alone")
            times: list[float] = []
            last: dict[str, object] = {}
            for _ in range(args.runs):
                took, last = one_run(sigterm, Path(tmp))
                times.append(took)
            runs = ", ".join(f"{t:.2f}" for t in times)
            print(f"  {case:<28} median {statistics.median(times):.2f} s, worst "
                  f"{max(times):.2f} s (runs: {runs})")
            print(f"    ended with: {str(last.get('error', ''))[:150]}")
            print(f"    torque_off {last.get('torque_off')}, signals {last.get('signals', 0)}")
    steal1, total1 = _steal_jiffies()
    load = os.getloadavg()
    steal = 100.0 * (steal1 - steal0) / max(1, total1 - total0)
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}, CPU steal {steal:.1f} % "
          "over the bench")


if __name__ == "__main__":
    main()
