"""``handrig bench bus`` end to end, briefly: every way runs, none beats the wire."""

from __future__ import annotations

import io
import os
import re

import pytest

from handrig.cli.bench_bus import Result, bench, wire_limit_hz

# A reply the emulator sent this much later than the wire would have carried it misses
# any read's budget here (4 servos at 1 Mbps: a whole cycle is 0.92 ms on the wire).
LATE_US = 1000.0


def _bench(puppet: bool) -> tuple[list[Result], str, float]:
    """The bench's results, what it printed, and the emulator's latest reply (us late)
    in the wire-timed ways (its closing line, as the bench prints it)."""
    out = io.StringIO()
    # 1 s per way: one host hiccup of some 50 ms (a fresh-clone run on a host losing
    # CPU to other guests failed 30 of 144 cycles in 0.3 s) stays well under a tenth
    results = bench(4, 1_000_000, 1.0, plain=True, puppet=puppet, out=out)
    text = out.getvalue()
    late = re.search(r"emulator: \d+ packets, .*reply late mean \d+ us max (\d+) us", text)
    assert late is not None, text
    return results, text, float(late.group(1))


@pytest.mark.parametrize("puppet", [False, True])
def test_bench_bus_runs_every_way_and_none_beats_the_wire(puppet: bool) -> None:
    results, text, late_us = _bench(puppet)
    if late_us > LATE_US and any(r.failed > r.cycles // 10 for r in results):
        # the emulator itself says it was held up past the reads' budget (a loaded host,
        # the MuJoCo puppet's physics beside it): the failed reads are the host's; the
        # measurement is taken once more
        print(f"emulator replies up to {late_us / 1000:.1f} ms late: once more\n{text}")
        results, text, late_us = _bench(puppet)
    _, limit = wire_limit_hz(4, 1_000_000)
    assert len(results) == 5 and results[0].name.startswith("handrig")
    for r in results:
        assert r.cycles > 0 and r.failed <= r.cycles // 10, (r, late_us)
        # the emulator holds every reply until the wire could have carried it
        assert r.hz <= 1.02 * limit, (r.name, r.hz, limit)
    assert ("drive the MuJoCo puppet" if puppet else "move kinematically") in text
    assert "host round trip, wire timing off" in text
    # whether the CPUs were kept awake is said (yes where the request may be made)
    awake = re.search(r"CPUs kept awake for every way \(.*\): (yes|no)", text)
    assert awake is not None, text
    device = os.environ.get("HANDRIG_CPU_LATENCY_DEVICE", "/dev/cpu_dma_latency")
    assert (awake.group(1) == "yes") == bool(device and os.access(device, os.W_OK)), text
    # the comparison with the SDK names the wire's cap on it (its own figures, printed)
    sdk = results[-1].hz
    said = re.search(r"SDK's Fast Sync Read: ([\d.]+)x the cycles/s \(the wire caps it at "
                     r"([\d.]+)x", text)
    assert said is not None, text
    assert float(said[1]) == pytest.approx(max(r.hz for r in results[:3]) / sdk, abs=0.006)
    assert float(said[2]) == pytest.approx(limit / sdk, abs=0.006)
