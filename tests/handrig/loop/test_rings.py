"""The loop's rings: SampleRing (the newest values in one float array, and numpy's
percentiles of them) and Ring (the newest items, indexed and sliced as a list of them)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from handrig.loop.stats import Ring, SampleRing


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


@pytest.mark.parametrize("size", [1, 3, 8])
def test_a_ring_indexes_and_slices_as_the_list_of_its_newest_items(size: int) -> None:
    for appended in range(20):
        ring: Ring[int] = Ring(size)
        for i in range(appended):
            ring.append(i)
        kept = list(range(appended))[-size:]
        assert list(ring) == kept and len(ring) == len(kept)
        for index in range(-len(kept) - 2, len(kept) + 2):
            if -len(kept) <= index < len(kept):
                assert ring[index] == kept[index]
            else:
                with pytest.raises(IndexError):
                    ring[index]
        for start, stop in itertools.product([None, -5, -3, -1, 0, 1, 5], [None, -1, 0, 2]):
            assert ring[start:stop] == kept[start:stop]
