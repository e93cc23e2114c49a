"""Fixed-size statistics: histogram percentiles against numpy, a ring of the newest."""

from __future__ import annotations

import math

import numpy as np
import pytest

from handrig.loop.stats import LogHistogram, Ring, RunStats


@pytest.mark.parametrize("name", ["lognormal", "uniform", "bimodal", "constant"])
def test_percentiles_are_within_a_few_percent_of_numpy(name: str) -> None:
    rng = np.random.default_rng(11)
    values = {
        "lognormal": rng.lognormal(math.log(100e-6), 0.6, 50_000),  # latencies around 100 us
        "uniform": rng.uniform(4.9e-3, 5.1e-3, 50_000),  # periods around 5 ms
        "bimodal": np.concatenate([rng.normal(90e-6, 5e-6, 40_000),
                                   rng.normal(2e-3, 1e-4, 1_000)]),
        "constant": np.full(1000, 50e-6),
    }[name]
    h = LogHistogram()
    for v in values:
        h.add(float(v))
    assert h.count == len(values)
    for q in (1, 10, 50, 90, 99, 99.9):
        want = float(np.percentile(values, q))
        assert h.percentile(q) == pytest.approx(want, rel=0.03), q
    assert h.percentile(0) == values.min() and h.percentile(100) == values.max()
    assert h.mean == pytest.approx(float(values.mean()), rel=1e-9)
    assert h.std == pytest.approx(float(np.std(values)), rel=1e-6, abs=1e-15)


def test_zero_negative_huge_and_nan_values_are_counted_safely() -> None:
    h = LogHistogram()
    assert math.isnan(h.percentile(50)) and math.isnan(h.std)
    for v in (0.0, -1e-6, 1e9, math.nan, 1e-3):
        h.add(v)
    assert h.count == 4  # the NaN is not a value
    assert h.percentile(0) == -1e-6 and h.percentile(100) == 1e9
    assert h.percentile(50) <= 1e-3


def test_memory_does_not_grow_with_the_number_of_values() -> None:
    import tracemalloc

    h = LogHistogram()
    tracemalloc.start()
    buckets = h.n_buckets
    for k in range(200_000):
        h.add(1e-6 * (1 + k % 5000))
    grown, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert h.n_buckets == buckets and h.count == 200_000
    assert grown < 10_000  # bytes still held after 200,000 values


def test_a_ring_keeps_the_newest_items_and_slices_like_a_list() -> None:
    r: Ring[int] = Ring(4)
    assert len(r) == 0 and r[-4:] == [] and not r
    for i in range(10):
        r.append(i)
    assert len(r) == 4 and r.total == 10
    assert list(r) == [6, 7, 8, 9] and r[-2:] == [8, 9] and r[-1] == 9


def test_run_stats_report_from_the_histograms() -> None:
    s = RunStats()
    for i in range(5000):
        s.latency.add(80e-6 + 1e-9 * i)
        s.latencies_s.append(80e-6)
        s.period.add(5e-3 + (1e-6 if i % 2 else -1e-6))
    assert s.latency_us(50) == pytest.approx(82.5, rel=0.02)
    assert s.jitter_us == pytest.approx(1.0, rel=1e-3)
    assert len(s.latencies_s) == 2048
