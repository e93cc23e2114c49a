"""The host bench's measurements, briefly, and its per-minute counts."""

from __future__ import annotations

import numpy as np

from bench.bench_host import NAP_S, SPIN_GAP_S, counts_per_min, naps, spin_gaps


def test_counts_are_per_minute_above_each_threshold() -> None:
    late = np.array([0.0001, 0.0006, 0.0015, 0.003])
    assert counts_per_min(late, 60.0) == [3.0, 2.0, 1.0]
    assert counts_per_min(late, 30.0) == [6.0, 4.0, 2.0]
    assert counts_per_min(np.array([]), 10.0) == [0.0, 0.0, 0.0]


def test_naps_and_spin_gaps_measure_the_clock() -> None:
    late = naps(0.05)
    # each nap lasts at least its 1 ms, so there are at most 50, and none ends early
    assert 5 <= len(late) <= 50 and late.min() > -1e-4
    assert late.max() < 1.0
    gaps = spin_gaps(0.05)
    assert (gaps > SPIN_GAP_S).all() and gaps.sum() < 0.05 + NAP_S
