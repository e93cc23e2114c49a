"""The piecewise fitting method (issue 42): a kinked relation is learnt with its kink,
controls pass through, and the shipped maps are the command's output."""

from __future__ import annotations

import numpy as np

from handrig import hand
from handrig.offline.fitting import PIECEWISE_NOISE_DEG, fit_map

CTRL = ("riIndexMCPy", "riPinkyMCPy")
PIP = hand.curve_index("riIndexPIPy")
RING = hand.curve_index("riRingMCPy")


def _kinked(n: int = 800, seed: int = 2) -> np.ndarray:
    """Index PIP follows its MCP at 0.3 deg/deg below 20 deg and 1.5 above (the median
    of the MCP is 20); ring MCP follows the pinky linearly."""
    rng = np.random.default_rng(seed)
    y = np.tile(np.linspace(-3.0, 3.0, 50), (n, 1))
    mcp = rng.uniform(0.0, 40.0, n)
    pinky = rng.uniform(0.0, 30.0, n)
    y[:, hand.curve_index(CTRL[0])] = mcp
    y[:, hand.curve_index(CTRL[1])] = pinky
    y[:, PIP] = 10 + 0.3 * mcp + 1.2 * np.maximum(mcp - 20.0, 0.0) + rng.normal(0, 0.3, n)
    y[:, RING] = 5 + 0.8 * pinky + rng.normal(0, 0.3, n)
    return y


def test_piecewise_learns_a_kink_that_a_linear_map_cannot() -> None:
    y = _kinked()
    m = fit_map(y, CTRL, "piecewise")
    assert m.piecewise and m.knots_deg is not None and m.hinge_gains is not None
    x = y[:, m.control_indices]
    np.testing.assert_allclose(m.knots_deg, np.median(x, axis=0))
    j = 0  # riIndexMCPy
    # both slopes (0.3 below the knot, 1.5 above), shrunk toward the mean pose (controls
    # off by 1.5 deg); the linear relation gets a far smaller kink than the kinked one
    below, above = m.gains[PIP, j], m.gains[PIP, j] + m.hinge_gains[PIP, j]
    assert 0.3 < below < 0.5 and 1.2 < above < 1.5 and m.hinge_gains[PIP, j] > 0.8
    assert abs(m.hinge_gains[RING, 1]) < 0.2 and 0.7 < m.gains[RING, 1] + m.hinge_gains[
        RING, 1] / 2 < 0.9
    err_pw = np.sqrt(np.mean((m.predict(x)[:, PIP] - y[:, PIP]) ** 2))
    lin = fit_map(y, CTRL, "ridge")
    err_lin = np.sqrt(np.mean((lin.predict(x)[:, PIP] - y[:, PIP]) ** 2))
    assert err_pw < 1.0 and err_lin > 2.5 * err_pw
    # controls pass through, and each curve is its mean at the controls' means
    for c in m.control_indices:
        assert m.gains[c].tolist() == [1.0 if k == c else 0.0 for k in m.control_indices]
        assert not m.hinge_gains[c].any()
    at_means = m.predict(m.control_means_deg[None, :])[0]
    np.testing.assert_allclose(at_means[[PIP, RING]], m.curve_means_deg[[PIP, RING]])
    assert f"controls off by {PIECEWISE_NOISE_DEG:g} deg" in m.fitting


def test_more_noise_shrinks_the_piecewise_map_toward_the_mean_pose() -> None:
    y = _kinked()
    a = fit_map(y, CTRL, "piecewise", piecewise_noise_deg=0.5)
    b = fit_map(y, CTRL, "piecewise", piecewise_noise_deg=8.0)
    assert a.hinge_gains is not None and b.hinge_gains is not None
    assert abs(b.gains[PIP, 0]) + abs(b.hinge_gains[PIP, 0]) < abs(a.gains[PIP, 0]) + abs(
        a.hinge_gains[PIP, 0])
