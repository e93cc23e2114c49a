"""One Euro filter: constant, step, fast motion, and agreement with the paper's scalar form."""

from __future__ import annotations

import math

import numpy as np
import pytest

from handrig.pose.filters import OneEuroFilter


def scalar_one_euro(xs, ts, min_cutoff, beta, d_cutoff):  # type: ignore[no-untyped-def]
    """The paper's algorithm, one channel, written independently of the module."""
    def alpha(fc: float, te: float) -> float:
        tau = 1.0 / (2 * math.pi * fc)
        return 1.0 / (1.0 + tau / te)

    out = [xs[0]]
    x_prev, dx_prev = xs[0], 0.0
    for i in range(1, len(xs)):
        te = ts[i] - ts[i - 1]
        dx = (xs[i] - x_prev) / te
        dx_hat = dx_prev + alpha(d_cutoff, te) * (dx - dx_prev)
        fc = min_cutoff + beta * abs(dx_hat)
        x_hat = x_prev + alpha(fc, te) * (xs[i] - x_prev)
        out.append(x_hat)
        x_prev, dx_prev = x_hat, dx_hat
    return out


def run(f: OneEuroFilter, xs: np.ndarray, ts: np.ndarray) -> np.ndarray:
    out = np.empty_like(xs)
    buf = np.empty(xs.shape[1])
    for i, t in enumerate(ts):
        out[i] = f(xs[i], float(t), buf)
    return out


def test_a_constant_passes_through() -> None:
    f = OneEuroFilter(3, min_cutoff_hz=0.5, beta=0.1)
    ts = np.arange(200) * 0.005
    xs = np.tile([10.0, -3.0, 0.0], (200, 1))
    np.testing.assert_array_equal(run(f, xs, ts), xs)


def test_a_step_is_smoothed_without_overshoot() -> None:
    f = OneEuroFilter(1, min_cutoff_hz=1.0, beta=0.0)
    ts = np.arange(100) * 0.01
    xs = np.zeros((100, 1))
    xs[10:] = 1.0
    y = run(f, xs, ts)[:, 0]
    a = 1.0 / (1.0 + (1.0 / (2 * math.pi)) / 0.01)  # alpha at 1 Hz, Te = 10 ms
    assert y[10] == pytest.approx(a)
    assert np.all(np.diff(y[10:]) > 0) and y.max() < 1.0
    assert y[-1] == pytest.approx(1 - (1 - a) ** 90)


def test_high_beta_tracks_fast_motion() -> None:
    ts = np.arange(200) * 0.005
    xs = (100.0 * ts)[:, None]  # a ramp at 100 units/s
    lag_low = xs[-1, 0] - run(OneEuroFilter(1, 1.0, 0.0), xs, ts)[-1, 0]
    lag_high = xs[-1, 0] - run(OneEuroFilter(1, 1.0, 1.0), xs, ts)[-1, 0]
    assert lag_low > 10.0
    assert lag_high < 0.2 * lag_low


@pytest.mark.parametrize("n", [3, 40])  # the plain-float path and the numpy path
def test_matches_the_scalar_algorithm_per_channel(n: int) -> None:
    rng = np.random.default_rng(3)
    ts = np.cumsum(rng.uniform(0.003, 0.012, 300))
    xs = np.cumsum(rng.normal(0, 2, (300, n)), axis=0)
    params = (rng.uniform(0.3, 3.0, n), rng.uniform(0.0, 0.5, n), rng.uniform(0.5, 2.0, n))
    y = run(OneEuroFilter(n, *params), xs, ts)
    for c in range(n):
        ref = scalar_one_euro(list(xs[:, c]), list(ts), params[0][c], params[1][c], params[2][c])
        np.testing.assert_allclose(y[:, c], ref, rtol=1e-12, atol=1e-9)


def test_time_that_does_not_advance_holds_the_output_and_reset_restarts() -> None:
    f = OneEuroFilter(2)
    f(np.array([0.0, 0.0]), 0.0)
    y1 = f(np.array([1.0, 1.0]), 0.01).copy()
    np.testing.assert_array_equal(f(np.array([5.0, 5.0]), 0.01), y1)
    f.reset()
    np.testing.assert_array_equal(f(np.array([7.0, 8.0]), 0.02), [7.0, 8.0])
    out = np.array([7.0, 8.0])
    assert f(out, 0.03, out) is out  # in place


@pytest.mark.parametrize("kw", [{"min_cutoff_hz": 0.0}, {"beta": -1.0},
                                {"d_cutoff_hz": math.nan}, {"min_cutoff_hz": [1.0, 2.0]}])
def test_bad_parameters(kw: dict) -> None:
    with pytest.raises(ValueError):
        OneEuroFilter(3, **kw)
