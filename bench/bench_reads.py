"""The driver's own cost of a present-state read: CPU in the reading thread per read.

20 servos at 4 Mbps on the emulated bus (a process of its own, wire timing on), the
driver pinned to the loop's CPU. Each way runs a goal Sync Write then a read, as the
loop's cycle does, for ``HANDRIG_BENCH_SECONDS`` (default 3 s): a whole read, and reads
of half the servos in turn (``read_state(part=(i, 2))``, the shipped ``read_parts =
2``). CPU is this thread's (``time.thread_time``: Python, the kernels and the
syscalls); the wall time includes the wire and the emulator. No reply poll (``spin_s``
0), as the app drives the bus.
"""

from __future__ import annotations

import os
import time

import numpy as np

from handrig.cli.bench_bus import EmulatorProcess, bench_rig
from handrig.devices.servo import DynamixelBus
from handrig.realtime import pinned_loop

N_SERVOS = 20
BAUD = 4_000_000


def run(port: str, parts: int, seconds: float) -> tuple[int, float, float, int]:
    """(reads, CPU us per read, wall us per read, reads with a stale servo asked)."""
    rig = bench_rig(N_SERVOS, BAUD)
    bus = DynamixelBus(port, rig, baud=BAUD, spin_s=0.0)  # as the app builds it
    bus.connect()
    try:
        goals = np.zeros(N_SERVOS)
        for k in range(20):  # the path warm, as in a running loop
            bus.write_goals_deg(goals)
            bus.read_state(part=(k % parts, parts))  # part (0, 1): a whole read
        reads = stale = 0
        cpu = 0.0
        t0 = time.perf_counter()
        end = t0 + seconds
        while time.perf_counter() < end:
            bus.write_goals_deg(goals)
            c0 = time.thread_time()
            state = bus.read_state(part=(reads % parts, parts))
            cpu += time.thread_time() - c0
            reads += 1
            stale += bool(state.stale.any())
        wall = time.perf_counter() - t0
    finally:
        bus.close()
    return reads, cpu / reads * 1e6, wall / reads * 1e6, stale


def main() -> None:
    seconds = float(os.environ.get("HANDRIG_BENCH_SECONDS", 3.0))
    emu = EmulatorProcess(N_SERVOS, BAUD)
    try:
        with pinned_loop():
            rows = [(label, run(emu.port, parts, seconds))
                    for label, parts in (("whole", 1), ("half the servos", 2))]
    finally:
        emu.close()
    print(f"{N_SERVOS} servos, {BAUD // 1_000_000} Mbps, emulated bus with wire timing, "
          f"{seconds:g} s per way (a goal Sync Write before each read)")
    print("| read | reads | CPU per read (us) | wall per write + read (us) | stale |")
    print("|---|---|---|---|---|")
    for label, (n, cpu_us, wall_us, stale) in rows:
        print(f"| {label} | {n} | {cpu_us:.0f} | {wall_us:.0f} | {stale} |")


if __name__ == "__main__":
    main()
