"""The clipped-linear map: each curve's output range, in the file, the expander and the
compiled servo step."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from handrig import hand
from handrig.errors import ConfigError
from handrig.pose.expand import DEFAULT_MAP, Expander
from handrig.pose.maps import LinearMap

PIP = hand.curve_index("riIndexPIPy")


@pytest.fixture(scope="module")
def shipped() -> LinearMap:
    return LinearMap.load(DEFAULT_MAP)


def test_shipped_map_clips_every_curve_but_the_controls(shipped: LinearMap) -> None:
    rng = shipped.output_range_deg()
    ctrl = shipped.control_indices
    assert np.isinf(rng[ctrl]).all()
    others = np.setdiff1d(np.arange(50), ctrl)
    assert np.isfinite(rng[others]).all() and (rng[others, 0] <= rng[others, 1]).all()
    lim = hand.curve_limits_deg()[others]
    assert (rng[others, 0] >= lim[:, 0]).all() and (rng[others, 1] <= lim[:, 1]).all()


def test_range_survives_the_file_and_an_inverted_one_is_refused(
        shipped: LinearMap, tmp_path: Path) -> None:
    p = shipped.save(tmp_path / "m.toml")
    back = LinearMap.load(p)
    assert back.curve_range_deg is not None and shipped.curve_range_deg is not None
    np.testing.assert_allclose(back.curve_range_deg, shipped.curve_range_deg, atol=1e-4)
    text = p.read_text()
    lo, hi = (round(float(v), 4) + 0.0 for v in shipped.curve_range_deg[PIP])
    bad = text.replace(f"range_deg = [{lo!r}, {hi!r}]", f"range_deg = [{hi!r}, {lo!r}]", 1)
    assert bad != text
    (tmp_path / "bad.toml").write_text(bad)
    with pytest.raises(ConfigError, match=r"riIndexPIPy\.range_deg"):
        LinearMap.load(tmp_path / "bad.toml")


def test_expander_clips_to_the_range_and_without_one_does_not(shipped: LinearMap) -> None:
    assert shipped.curve_range_deg is not None
    far = shipped.control_means_deg + 40.0  # far past the training range: extrapolates
    clipped = Expander(shipped).expand(far).copy()
    free = Expander(replace(shipped, curve_range_deg=None)).expand(far).copy()
    lo, hi = shipped.curve_range_deg[PIP]
    assert lo <= clipped[PIP] <= hi
    assert free[PIP] > hi  # the check can fail: unclipped, the map leaves the range
    many = Expander(shipped).expand_many(np.tile(far, (3, 1)))
    np.testing.assert_allclose(many, np.tile(clipped, (3, 1)))
    np.testing.assert_allclose(shipped.predict(far[None])[0, PIP], clipped[PIP])
