"""What the host lets any loop do: how late a thread on the loop's CPU wakes, and how
long it is held off the CPU while it runs.

On the loop's CPU, with the loop's own settings (pinned, SCHED_FIFO where allowed,
1 us timer slack: :mod:`handrig.realtime`), two measurements of the same length:

* **naps**: sleep 1 ms in ``select`` (as the loop waits for a frame or a reply) and
  count how late each wake-up is;
* **spin**: a tight loop reading the clock, and the gaps in it (the thread was not
  running: the hypervisor, an interrupt, a kernel thread).

A 500 Hz glove leaves 2 ms between frames: a wake-up more than about 2 ms late, or a
gap that long, lets the next frame come before the loop has written the one before,
whatever the loop does. The counts are per minute, so runs of any length compare.
``HANDRIG_BENCH_SECONDS`` sets each measurement's length (default 10 s).
"""

from __future__ import annotations

import os
import select
import time

import numpy as np

from bench import rig_steps
from handrig.realtime import pinned_loop, realtime_priority

NAP_S = 0.001
THRESHOLDS_S = (0.0005, 0.001, 0.002)
SPIN_GAP_S = 0.0002  # a clock read this long after the one before: the thread was off


def naps(seconds: float) -> np.ndarray:
    """How late each 1 ms ``select`` sleep woke, in seconds."""
    late = []
    clock = time.perf_counter
    end = clock() + seconds
    while (t := clock()) < end:
        select.select([], [], [], NAP_S)
        late.append(clock() - t - NAP_S)
    return np.array(late)


def spin_gaps(seconds: float) -> np.ndarray:
    """The gaps longer than ``SPIN_GAP_S`` between clock reads of a tight loop."""
    gaps = []
    clock = time.perf_counter
    prev = clock()
    end = prev + seconds
    while prev < end:
        t = clock()
        if t - prev > SPIN_GAP_S:
            gaps.append(t - prev)
        prev = t
    return np.array(gaps)


def counts_per_min(values: np.ndarray, seconds: float) -> list[float]:
    """How many of ``values`` exceed each of :data:`THRESHOLDS_S`, per minute."""
    return [round(float(np.sum(values > th)) * 60.0 / seconds, 1) for th in THRESHOLDS_S]


def main() -> None:
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", 10.0))
    with pinned_loop() as cpu, realtime_priority() as fifo:
        before = rig_steps.cpu_times()
        late = naps(seconds)
        gaps = spin_gaps(seconds)
        steal = rig_steps.steal_percent(before, rig_steps.cpu_times())
    heads = " | ".join(f"> {th * 1e3:g} ms" for th in THRESHOLDS_S)
    print(f"loop CPU {cpu}, SCHED_FIFO {'yes' if fifo else 'no'}, {seconds:g} s each; "
          f"steal {steal} %")
    print(f"| what | events per minute {heads} | max (ms) |")
    print("|---|" + "---|" * len(THRESHOLDS_S) + "---|")
    for what, values in ((f"1 ms sleep woke late ({len(late)} naps)", late),
                         ("running thread held off the CPU", gaps)):
        top = f"{values.max() * 1e3:.2f}" if len(values) else "-"
        row = " | ".join(str(c) for c in counts_per_min(values, seconds))
        print(f"| {what} | {row} | {top} |")


if __name__ == "__main__":
    main()
