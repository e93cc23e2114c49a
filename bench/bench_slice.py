"""How late a normal (not SCHED_FIFO) thread wakes beside a busy one on its CPU, with
the fair scheduler's default slice and with handrig's short one.

Without root, the loop, the emulated bus's thread and the glove emulator's run at
normal priority and ask for a 0.1 ms slice (:func:`handrig.realtime.short_slice`;
Linux 6.12+). Here a process spins on one CPU and this thread, pinned beside it,
sleeps 1 ms in ``select`` (as the loop waits for a frame or a reply) and counts how
late each wake-up is; default and short slice alternate, ``HANDRIG_BENCH_ROUNDS``
rounds (default 2) of ``HANDRIG_BENCH_SECONDS`` each (default 3 s). The thread keeps
SCHED_OTHER even as root: what a user without root gets is measured.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np

from bench.bench_host import THRESHOLDS_S, counts_per_min, naps
from handrig.realtime import SHORT_SLICE_NS, fair_slice_ns


def main() -> None:
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", 3.0))
    rounds = int(os.environ.get("HANDRIG_BENCH_ROUNDS", 2))
    default = fair_slice_ns()
    if default is None or fair_slice_ns(SHORT_SLICE_NS) is None \
            or fair_slice_ns() != SHORT_SLICE_NS:
        print("this kernel takes no per-thread fair slice (Linux 6.12+, x86_64 or aarch64): "
              "nothing to compare")
        return
    fair_slice_ns(default)
    cpus_before = os.sched_getaffinity(0)
    cpu = max(cpus_before)
    os.sched_setaffinity(0, {cpu})
    spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"],
                               preexec_fn=lambda: os.sched_setaffinity(0, {cpu}))
    heads = " | ".join(f"> {th * 1e3:g} ms" for th in THRESHOLDS_S)
    print(f"CPU {cpu}, a process spinning on it; 1 ms sleeps, {seconds:g} s a row; "
          f"kernel {os.uname().release}")
    print(f"| slice | wake-up late p50 / p99 (us) | events per minute {heads} | max (ms) |")
    print("|---|---|" + "---|" * len(THRESHOLDS_S) + "---|")
    try:
        naps(0.3)  # the spinner is running
        for _ in range(rounds):
            for name, ns in ((f"default ({default / 1e6:g} ms)", default),
                             (f"short ({SHORT_SLICE_NS / 1e6:g} ms)", SHORT_SLICE_NS)):
                fair_slice_ns(ns)
                late = naps(seconds)
                p50, p99 = np.percentile(late, [50, 99]) * 1e6
                row = " | ".join(str(c) for c in counts_per_min(late, seconds))
                print(f"| {name} | {p50:.0f} / {p99:.0f} | {row} | {late.max() * 1e3:.2f} |",
                      flush=True)
    finally:
        fair_slice_ns(default)
        os.sched_setaffinity(0, cpus_before)  # `python -m bench` runs the next bench here
        spinner.kill()
        spinner.wait()


if __name__ == "__main__":
    main()
