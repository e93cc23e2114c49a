"""`handrig demo --render`: the count it prints is the tiles drawn, each labelled with
its frame's time (rendering needs EGL or OSMesa; the test skips without them)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from handrig.app import simulator
from sim.render import MAX_TILES, picked

CLI = [sys.executable, "-m", "handrig.cli"]


def test_tiles_drawn_is_what_render_strip_draws() -> None:
    for n in (1, MAX_TILES, MAX_TILES + 1, 40):
        assert simulator.tiles_drawn(n) == len(picked(n)) == min(n, MAX_TILES)


@pytest.mark.slow
def test_demo_render_says_how_many_tiles_and_when(tmp_path: Path) -> None:
    out = tmp_path / "strip.png"
    run = subprocess.run([*CLI, "demo", "--frames", "300", "--render", str(out)],
                         capture_output=True, text=True, timeout=300)
    if "no render:" in run.stderr:
        pytest.skip(run.stderr.strip().splitlines()[-1])
    assert run.returncode in (0, 1), run.stderr  # 1: a loaded machine's bus trouble
    said = re.search(r"rendered (\d+) frames of the simulated hand to (\S+) "
                     r"\(t = ([\d.]+) to ([\d.]+) s\)", run.stdout)
    assert said, run.stdout[-2000:]
    assert Path(said[2]) == out and out.is_file()
    if run.returncode == 0:
        # a snapshot every 50 cycles (300 frames / 6) once the servos have been read: as
        # many as the run's cycles say, or one fewer (about 500 cycles, 300 and the 1 s
        # ease, on a quiet machine; a loaded one may run fewer in the ease)
        cycles = re.search(r"^frames +(\d+) in ", run.stdout, flags=re.M)
        assert cycles, run.stdout[-2000:]
        snaps = int(cycles[1]) // 50
        assert int(said[1]) in {simulator.tiles_drawn(snaps - 1), simulator.tiles_drawn(snaps)}
    # 300 frames at 200 Hz, then the ease: about 2.5 s, within the run's own length (a
    # loaded machine's run lasts longer)
    run_s = re.search(r"^frames +\d+ in ([\d.]+) s", run.stdout, flags=re.M)
    assert run_s, run.stdout[-2000:]
    assert float(said[3]) < float(said[4]) <= max(3.0, float(run_s[1]) + 0.1)
