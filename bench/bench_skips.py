"""Why a glove frame was skipped: each skip event of a 500 Hz run, with what came before it.

Runs the glove-triggered rig of :mod:`bench.bench_rig` (500 Hz glove, 4 Mbps bus, 20
emulated servos, both emulators in processes of their own) and records, for every
cycle, when its write went out, when it was done (outputs, the read or housekeeping
after the write), how many state reads it made and the loop thread's CPU time. Each
cycle whose sample superseded frames the loop should have written (the cycle's
``frames_skipped`` count rose) is then put down to what the cycle before it did:

* ``read``: it made a state read and ran longer than a period after its write;
* ``after write``: it ran longer than a period after its write without a read
  (housekeeping, outputs, a stall inside them);
* ``host``: it was done in time, and the loop's thread used less than half the wall
  time until the next cycle: the frames waited while the thread was not running.

It also prints what catching up costs (``[loop] catch_up``): for each cycle that wrote a
frame a newer one had overtaken, how long after its write the next write went out.

The cycle's code is wrapped in this process only (``Cycle._after_write``); nothing in
the product changes. ``HANDRIG_BENCH_SECONDS`` sets the run's length (default 20 s).
"""

from __future__ import annotations

import os
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from bench import bench_rig, rig_steps
from handrig.loop import cycle as cycle_module

RATE_HZ = 500.0
BAUD = 4_000_000


def classify(rows: np.ndarray, period_s: float) -> list[tuple[str, int, float, float]]:
    """(cause, frames, the previous cycle's time after its write, its CPU share) for
    each skip event. ``rows``: per cycle (written, done, reads, skipped, cpu)."""
    written, done, reads, skipped, cpu = rows.T
    out = []
    for i in range(1, len(rows)):
        frames = int(skipped[i] - skipped[i - 1])
        if frames <= 0 or i < 2:
            continue
        after = done[i - 1] - written[i - 1]
        read = reads[i - 1] > reads[i - 2]
        wall = written[i] - written[i - 1]
        share = (cpu[i] - cpu[i - 1]) / wall if wall > 0 else 1.0
        if after > period_s:
            cause = "read" if read else "after write"
        elif share < 0.5:
            cause = "host"
        else:
            cause = "loop busy"
        out.append((cause, frames, after, share))
    return out


def main() -> None:
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", 20.0))
    rows: list[tuple[float, float, int, int, float]] = []
    caught: list[int] = []  # the rows of catch-up cycles
    original = cycle_module.Cycle._after_write

    def after_write(self: Any, tick: Any, sample: Any, mode: Any, goals: Any,
                    bus_clamps: int) -> None:
        written = time.perf_counter()
        cpu = time.thread_time()
        original(self, tick, sample, mode, goals, bus_clamps)
        rows.append((written, time.perf_counter(), self.stats.reads,
                     self.stats.frames_skipped, cpu))
        if tick.catch_up:
            caught.append(len(rows) - 1)

    cycle_module.Cycle._after_write = after_write  # type: ignore[method-assign]
    try:
        with tempfile.TemporaryDirectory(prefix="bench_skips_") as tmp:
            before = rig_steps.cpu_times()
            result = bench_rig.run_step_case(bench_rig.Case("glove", RATE_HZ, BAUD),
                                             seconds, Path(tmp))
            steal = rig_steps.steal_percent(before, rig_steps.cpu_times())
    finally:
        cycle_module.Cycle._after_write = original  # type: ignore[method-assign]
    s = result["summary"]
    events = classify(np.array(rows), 1.0 / RATE_HZ)
    print(f"glove-triggered rig, {RATE_HZ:g} Hz glove, {BAUD // 1_000_000} Mbps, 20 emulated "
          f"servos, {seconds:g} s; steal {steal} %")
    print(f"frames {s['frames']}, skipped by the loop {s['frames_skipped']} "
          f"(in the glove's bursts {s.get('frames_in_bursts', 0)}, caught up "
          f"{s.get('frames_caught_up', 0)}), reads/s "
          f"{s['reads_per_s']}, writes delayed by reads {s['writes_delayed_by_reads']}")
    frames = Counter[str]()
    counts = Counter[str]()
    for cause, n, _, _ in events:
        frames[cause] += n
        counts[cause] += 1
    print("| cause | skip events | frames | previous cycle after its write, p50 / max (ms) |")
    print("|---|---|---|---|")
    for cause in ("read", "after write", "host", "loop busy"):
        after = [a for c, _, a, _ in events if c == cause]
        spread = (f"{np.median(after) * 1e3:.2f} / {max(after) * 1e3:.2f}" if after
                  else "-")
        print(f"| {cause} | {counts[cause]} | {frames[cause]} | {spread} |")
    written = np.array([r[0] for r in rows])
    gaps = np.array([written[i + 1] - written[i] for i in caught if i + 1 < len(written)])
    if len(gaps):
        print(f"catch-up cycles {len(gaps)}: the next write went out "
              f"{np.median(gaps) * 1e6:.0f} us (p50), {np.percentile(gaps, 90) * 1e6:.0f} us "
              f"(p90), {gaps.max() * 1e6:.0f} us (max) after the caught-up frame's")
    else:
        print("catch-up cycles 0")


if __name__ == "__main__":
    main()
