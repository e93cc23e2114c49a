"""The firmware stamps each frame with its ADC burst's middle, and its head is on the wire
while the burst runs: checked from outside the firmware, by the harness watching the
emulated chip's ADC conversions and UART (sim/avr_glove/harness.c, --timing).

Skipped, naming `make firmware-deps`, where the AVR toolchain or simavr is missing.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sim.avr_glove import AvrGlove, build, toolchain_missing

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "config" / "recordings" / "demo_glove.csv"


@pytest.fixture(scope="module")
def chip_built() -> None:
    missing = toolchain_missing()
    if missing:
        pytest.skip(missing)
    build()


def test_each_frame_is_stamped_with_its_bursts_middle_and_sent_while_it_runs(
        chip_built: None, tmp_path: Path):
    timing = tmp_path / "timing.txt"
    chip = AvrGlove(DEMO, seconds=1.0, speed=2.0, timing=timing)
    with chip:
        frames = chip.read_frames()
    # per frame: number, ..., [6] the middle in chip time, [9] on the micros() clock,
    # [10] the frame's bytes out before the burst's last conversion started
    rows = {int(r[0]): r for r in (line.split() for line in timing.read_text().splitlines())}
    # frame k (seq k - 1 from reset); the first two use the start-up guess of the span
    steady = [(f, rows[f.seq + 1]) for f in frames if f.seq >= 2 and f.seq + 1 in rows]
    assert len(steady) >= 150, (len(frames), len(rows))
    off_us = np.array([f.timestamp_us - float(r[9]) for f, r in steady])
    # micros() counts in 4 us steps
    assert abs(np.median(off_us)) <= 8.0 and np.percentile(np.abs(off_us), 98) <= 15.0, (
        np.percentile(off_us, [0, 2, 50, 98, 100]))
    early = np.array([int(r[10]) for _, r in steady])
    assert np.all(early >= 1) and np.median(early) >= 9, np.bincount(early)
