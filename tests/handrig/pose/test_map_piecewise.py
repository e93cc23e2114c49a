"""Piecewise-linear maps (issue 42): the file, the expander and the compiled servo step
agree with the map's own definition."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from handrig.app.parts import build_parts
from handrig.errors import ConfigError, DataError
from handrig.pose import kernels
from handrig.pose.expand import DEFAULT_MAP, Expander
from handrig.pose.maps import LinearMap
from tests.handrig.pose.test_pipeline import NumpyServoStep


def _piecewise(seed: int = 3) -> LinearMap:
    """The shipped map's controls and means, with knots and hinge gains of its own."""
    base = LinearMap.load(DEFAULT_MAP)
    rng = np.random.default_rng(seed)
    k = len(base.controls)
    hinge = rng.normal(0.0, 0.1, (50, k))
    hinge[base.control_indices] = 0.0  # a control passes through
    gains = base.gains.copy()
    gains[~np.isin(np.arange(50), base.control_indices)] = rng.normal(0.0, 0.1, (50 - k, k))
    return replace(base, gains=gains, knots_deg=base.control_means_deg + rng.normal(0, 3, k),
                   hinge_gains=hinge, method="piecewise")


def _by_definition(m: LinearMap, x: np.ndarray) -> np.ndarray:
    """The module docstring's formula, term by term, clipped to the output range."""
    assert m.knots_deg is not None and m.hinge_gains is not None
    out = np.tile(m.curve_means_deg, (len(x), 1))
    for j in range(len(m.controls)):
        out += np.outer(x[:, j] - m.control_means_deg[j], m.gains[:, j])
        hinge = np.maximum(x[:, j] - m.knots_deg[j], 0) - max(
            m.control_means_deg[j] - m.knots_deg[j], 0)
        out += np.outer(hinge, m.hinge_gains[:, j])
    rng = m.output_range_deg()
    return np.clip(out, rng[:, 0], rng[:, 1])


def test_a_piecewise_map_is_its_formula_in_the_file_the_expander_and_at_the_means(
        tmp_path: Path) -> None:
    m = _piecewise()
    rng = np.random.default_rng(0)
    x = m.control_means_deg + rng.uniform(-25, 25, (300, len(m.controls)))
    want = _by_definition(m, x)
    np.testing.assert_allclose(m.predict(x), want, atol=1e-9)
    loaded = LinearMap.load(m.save(tmp_path / "pw.toml"))
    assert loaded.piecewise and "knots_deg = [" in (tmp_path / "pw.toml").read_text()
    np.testing.assert_allclose(loaded.predict(x), want, atol=0.01)  # rounded in the file
    # at the controls' means every curve is its mean (the hinge terms are centred there)
    at_means = m.predict(m.control_means_deg[None, :])[0]
    mask = np.isfinite(m.output_range_deg()[:, 0])
    lo, hi = m.output_range_deg()[mask].T
    np.testing.assert_allclose(at_means[mask], np.clip(m.curve_means_deg[mask], lo, hi))
    ex = Expander(m)
    lim = np.array([ex.low_deg, ex.high_deg]).T
    clamped = np.clip(want, lim[:, 0], lim[:, 1])
    np.testing.assert_allclose(ex.expand_many(x), clamped, atol=1e-9)
    for row, w in zip(x[:40], clamped[:40], strict=True):
        np.testing.assert_allclose(ex.expand(row), w, atol=1e-9)
    # the linear map (no hinge) differs: the test would notice hinges being dropped
    assert np.abs(Expander(replace(m, knots_deg=None, hinge_gains=None)).expand_many(x)
                  - clamped).max() > 0.5
    assert ex.training_range().frames == 300 + 40


def test_the_compiled_servo_step_runs_a_piecewise_map(tmp_path: Path) -> None:
    path = _piecewise().save(tmp_path / "pw.toml")
    parts = build_parts(map_file=path)
    pl = parts.pipeline
    assert pl.servo_path.knots.shape == (5,) and pl.servo_path.a.shape[0] == 10
    reference = NumpyServoStep(pl.servo_path, parts.sag, pl.servo_low, pl.servo_high,
                               pl.slew_deg_s)
    rng = np.random.default_rng(5)
    k = len(pl.expander.controls)
    for i in range(400):
        controls = pl.expander.control_means_deg + rng.uniform(-30, 30, k)
        if i % 29 == 0:
            controls[rng.integers(k)] = np.nan
        got = pl.servo_targets(controls, 20.0, 45.0, 0.01).copy()
        np.testing.assert_allclose(got, reference(controls, 20.0, 45.0, 0.01), atol=1e-9)
    assert pl.rejected == reference.rejected > 0


def test_hinge_features_keep_a_bad_control_bad() -> None:
    out = np.zeros(6)
    kernels.hinge_features(np.array([1.0, 5.0, np.nan]), np.array([2.0, 2.0, 0.0]), out)
    assert out[:2].tolist() == [1.0, 5.0] and out[3:5].tolist() == [0.0, 3.0]
    assert np.isnan(out[2]) and np.isnan(out[5])


def test_a_map_file_with_hinges_but_no_knots_is_refused(tmp_path: Path) -> None:
    text = _piecewise().to_toml()
    bad = tmp_path / "bad.toml"
    bad.write_text("\n".join(x for x in text.splitlines() if not x.startswith("knots_deg")))
    with pytest.raises(ConfigError, match="knots_deg") as exc:
        LinearMap.load(bad)
    assert "bad.toml" in str(exc.value) and "hinge_gains" in str(exc.value)
    with pytest.raises(DataError, match="both knots_deg and hinge_gains"):
        replace(_piecewise(), knots_deg=None)
    wrong = text.replace("knots_deg = [", "knots_deg = [1.0, ")
    (tmp_path / "wrong.toml").write_text(wrong)
    with pytest.raises(ConfigError, match="one knot per control"):
        LinearMap.load(tmp_path / "wrong.toml")
