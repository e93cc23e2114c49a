"""``handrig bench bus`` end to end, briefly: every way runs, none beats the wire."""

from __future__ import annotations

import io

import pytest

from handrig.cli.bench_bus import bench, wire_limit_hz


@pytest.mark.parametrize("puppet", [False, True])
def test_bench_bus_runs_every_way_and_none_beats_the_wire(puppet: bool) -> None:
    out = io.StringIO()
    # 1 s per way: one host hiccup of some 50 ms (a fresh-clone run on a host losing
    # CPU to other guests failed 30 of 144 cycles in 0.3 s) stays well under a tenth
    results = bench(4, 1_000_000, 1.0, plain=True, puppet=puppet, out=out)
    text = out.getvalue()
    _, limit = wire_limit_hz(4, 1_000_000)
    assert len(results) == 5 and results[0].name.startswith("handrig")
    for r in results:
        assert r.cycles > 0 and r.failed <= r.cycles // 10, r
        # the emulator holds every reply until the wire could have carried it
        assert r.hz <= 1.02 * limit, (r.name, r.hz, limit)
    assert ("drive the MuJoCo puppet" if puppet else "move kinematically") in text
    assert "host round trip, wire timing off" in text
