"""The read-cost bench, briefly: both ways read the servos they ask, and count their CPU."""

from __future__ import annotations

from bench.bench_reads import BAUD, N_SERVOS, run
from handrig.cli.bench_bus import EmulatorProcess


def test_both_ways_read_and_count_their_cpu() -> None:
    emu = EmulatorProcess(N_SERVOS, BAUD)
    try:
        whole = run(emu.port, 1, 0.3)
        half = run(emu.port, 2, 0.3)
    finally:
        emu.close()
    for reads, cpu_us, wall_us, stale in (whole, half):
        assert reads > 20 and stale <= reads // 10
        assert 0.0 < cpu_us <= wall_us  # the thread's CPU is part of the wall time
