"""Start-up of real ``handrig`` processes, from outside: launch to exit, port, first write.

Each case launches ``python -m handrig.cli ...`` (what the ``handrig`` script runs)
as a fresh process, ``--runs`` times (default 5; ``HANDRIG_BENCH_RUNS``), and prints
the median and the worst wall time from ``Popen`` to (a run that fails is run again,
up to 3 times, and each failure printed):

* ``help``: ``handrig --help`` exiting;
* ``demo``: ``handrig demo --frames 1 --json`` exiting (its emulators started and
  stopped, one loop cycle, and the 0.3 s ease in and the 1 s ease to the relaxed
  pose that every run has at its ends);
* ``sim-bus`` and ``sim-glove``: the emulators the demo starts, to their ``port:``
  line (the start-up a simulated rig waits for);
* ``first write``: ``handrig run --bus PTY --glove PTY --frames 1 --json`` to the
  first Sync Write of Goal Position bytes arriving on the bus: the bus (the rig's
  20 emulated servos at its baud, wire timing on, no puppet) and the glove (the demo
  recording at 200 Hz) are emulated in this process (``sim.dxl_bus.SimBus``'s
  ``on_sync_write``, stamped with CLOCK_MONOTONIC as the launch is), so this is the
  run's own start-up: imports, configs, kernels, opening both ports, commissioning
  the servos, torque on, the first frame. Then the same run to its exit.

``--base COMMIT`` runs every case on that commit too (a temporary git worktree, the
same Python and packages, ``PYTHONPATH`` set to each side's tree), base and this tree
alternating run by run, after one warm-up run of each case on each side (dropped: a
fresh worktree has no numba cache); the table then has both sides' columns. Load
average and steal (``/proc/stat``) over the whole bench are printed with it.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from bench.compare import base_worktree, resolve_commit
from bench.rig_steps import cpu_times, steal_percent

ROOT = Path(__file__).resolve().parent.parent
GOAL_POSITION = 116  # X-series control table: Goal Position (4 bytes)
RECORDING = "config/recordings/demo_glove.csv"
TIMEOUT_S = 60.0
ATTEMPTS = 3  # a run that fails is run again (each failure is counted and printed)


class RunFailed(Exception):
    """One launched process did not do what the case times (its stderr in the message)."""


def _env(root: Path) -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(root))


def _cmd(argv: Sequence[str]) -> list[str]:
    return [sys.executable, "-m", "handrig.cli", *argv]


def to_exit(root: Path, argv: Sequence[str]) -> float:
    """Seconds from launching ``handrig ARGV`` in ``root`` to its exit (status 0)."""
    t0 = time.monotonic()
    out = subprocess.run(_cmd(argv), cwd=root, env=_env(root), capture_output=True,
                         text=True, timeout=TIMEOUT_S)
    took = time.monotonic() - t0
    if out.returncode != 0:
        raise RunFailed(f"handrig {' '.join(argv)} in {root} failed ({out.returncode}): "
                         f"{out.stderr[-2000:]}")
    return took


def to_port(root: Path, argv: Sequence[str]) -> float:
    """Seconds from launching ``handrig ARGV`` (an emulator) to its ``port:`` line."""
    t0 = time.monotonic()
    proc = subprocess.Popen(_cmd(argv), cwd=root, env=_env(root), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        took = time.monotonic() - t0
        if not line.startswith("port: "):
            proc.kill()
            raise RunFailed(f"handrig {' '.join(argv)} in {root} did not print its port: "
                             f"{line!r} {proc.communicate(timeout=5)[1][-2000:]}")
        return took
    finally:
        if proc.poll() is None:
            proc.terminate()
        proc.communicate(timeout=10)


def to_first_write(root: Path) -> tuple[float, float]:
    """``handrig run`` on this process's emulated bus and glove: seconds from its launch
    to the first Goal Position Sync Write arriving on the bus, and to its exit."""
    from handrig.app import simulator
    from handrig.config.rig import load_rig_config
    from handrig.devices.glove_recording import read_glove_recording
    from sim.dxl_bus import SimBus

    rig = load_rig_config(ROOT / "config" / "rig.toml")
    bus = SimBus.from_rig(rig, wire_timing=True)
    first: list[float] = []
    arrived = threading.Event()

    def on_sync_write(t_s: float, address: int, items: list[tuple[int, bytes]]) -> None:
        if address == GOAL_POSITION and not first:
            first.append(t_s)
            arrived.set()

    bus.on_sync_write = on_sync_write
    glove = simulator.glove_emulator(read_glove_recording(ROOT / RECORDING), rate_hz=200.0,
                                     loop=True)
    bus.start()
    try:
        with glove:
            argv = ["run", "--rig", str(ROOT / "config" / "rig.toml"), "--bus", bus.port_path,
                    "--glove", glove.port_path, "--frames", "1", "--json"]
            t0 = time.monotonic()
            out = subprocess.run(_cmd(argv), cwd=root, env=_env(root), capture_output=True,
                                 text=True, timeout=TIMEOUT_S)
            took = time.monotonic() - t0
    finally:
        bus.stop()
    if out.returncode != 0 or not first:
        raise RunFailed(f"handrig run in {root} failed ({out.returncode}, first write "
                         f"{'seen' if first else 'never seen'}): {out.stderr[-2000:]}")
    return first[0] - t0, took


def cases() -> list[tuple[str, Callable[[Path], list[float]]]]:
    """(label, measure) pairs; a measure returns one or more figures (seconds)."""
    recording = str(ROOT / RECORDING)
    rig = str(ROOT / "config" / "rig.toml")
    return [
        ("handrig --help, to exit", lambda r: [to_exit(r, ["--help"])]),
        ("sim-bus --wire-timing, to its port", lambda r: [to_port(
            r, ["sim-bus", "--rig", rig, "--wire-timing"])]),
        ("sim-glove (200 Hz), to its port", lambda r: [to_port(
            r, ["sim-glove", recording, "--rate", "200"])]),
        ("demo --frames 1 --json, to exit", lambda r: [to_exit(
            r, ["demo", "--frames", "1", "--json"])]),
        ("run --frames 1, to first goal write|run --frames 1, to exit",
         lambda r: list(to_first_write(r))),
    ]


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m bench startup",
                                description=__doc__.split("\n")[0] if __doc__ else None)
    p.add_argument("--base", default=None, metavar="COMMIT",
                   help="also time this commit (a temporary worktree), alternating with "
                   "this tree")
    p.add_argument("--runs", type=int, default=int(os.environ.get("HANDRIG_BENCH_RUNS", 5)),
                   help="runs of each case on each side (default 5)")
    return p.parse_args(sys.argv[1:] if argv is None else argv)


def _fmt(xs: list[float]) -> str:
    return f"{statistics.median(xs):11.2f} {max(xs):6.2f}"


def measure(sides: dict[str, Path], runs: int) -> None:
    names = list(sides)
    labels: list[str] = []
    figures: dict[tuple[str, str], list[float]] = {}
    failures: list[str] = []

    def attempt(run: Callable[[Path], list[float]], root: Path) -> list[float]:
        for k in range(ATTEMPTS):
            try:
                return run(root)
            except RunFailed as exc:
                failures.append(str(exc).strip().splitlines()[-1][-300:])
                if k == ATTEMPTS - 1:
                    raise SystemExit(f"{exc}\n(failed {ATTEMPTS} times in a row)") from None
        raise AssertionError("unreachable")

    for label, run in cases():
        parts = label.split("|")
        labels += parts
        if len(sides) > 1:  # warm-up: a fresh worktree compiles its numba cache
            for root in sides.values():
                attempt(run, root)
        for k in range(runs):
            for side in (names if k % 2 == 0 else names[::-1]):
                for part, value in zip(parts, attempt(run, sides[side]), strict=True):
                    figures.setdefault((part, side), []).append(value)
    width = max(len(x) for x in labels)
    head = "".join(f"  {s + ' median':>11} {'worst':>6}" for s in names)
    print(f"  {'case (wall seconds from launch)':<{width}}{head}")
    for part in labels:
        print(f"  {part:<{width}}" + "".join(f"  {_fmt(figures[(part, s)])}" for s in names))
    print(f"runs that failed and were run again: {len(failures)}"
          + "".join(f"\n  {f}" for f in failures))


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(argv)
    if args.runs < 1:
        raise SystemExit("--runs must be at least 1")
    load0, before = os.getloadavg(), cpu_times()
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                          capture_output=True, text=True).stdout.strip()
    if args.base is None:
        print(f"this tree ({head}), {args.runs} runs per case; median and worst")
        measure({"new": ROOT}, args.runs)
    else:
        sha = resolve_commit(args.base)
        with base_worktree(sha, prefix="bench_startup_") as base_root:
            print(f"base {sha[:9]} (a worktree) against new: this tree ({head}); "
                  f"{args.runs} runs per case per side, alternating, after a warm-up "
                  "run each; median and worst")
            measure({"base": base_root, "new": ROOT}, args.runs)
    steal = steal_percent(before, cpu_times())
    print(f"load average {load0[0]:.2f} at the start, {os.getloadavg()[0]:.2f} at the end; "
          f"steal {steal} %")


if __name__ == "__main__":
    main()
