"""SampleRing: the newest values in one float array, and numpy's percentiles of them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from handrig.loop.stats import SampleRing


@pytest.mark.parametrize("appended", [1, 5, 1000, 2048, 3001, 7000])
def test_percentiles_of_the_newest_are_numpys(appended: int) -> None:
    ring = SampleRing(2048)
    values = np.random.default_rng(appended).exponential(1e-4, appended)
    for v in values:
        ring.append(float(v))
    assert len(ring) == min(appended, 2048) and ring.total == appended
    for k in (1, 2, 999, 1000, 2048, 5000):
        newest = values[-min(k, 2048):]
        np.testing.assert_array_equal(ring.newest(k), newest)
        got = ring.percentiles((0.0, 50.0, 90.0, 99.0, 100.0), k)
        np.testing.assert_allclose(got, np.percentile(newest, [0, 50, 90, 99, 100]),
                                   rtol=0.0, atol=1e-18)


def test_an_empty_ring_has_no_percentiles() -> None:
    ring = SampleRing(8)
    assert all(math.isnan(v) for v in ring.percentiles((50.0, 99.0)))
    assert ring.newest(3).size == 0
