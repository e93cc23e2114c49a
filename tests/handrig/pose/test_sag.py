"""SagGrid: bilinear lookup on the stored coordinates, wrap, poles, errors, shipped grid."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from handrig.errors import DataError
from handrig.hand import DOF_NAMES, dof_limits_deg
from handrig.pose.sag import SAG_GRID, SagGrid

# Table 2 in the vocabulary convention: DOF -> (value in its calibration orientation).
CALIBRATED = {
    (-90.0, 0.0): {"riIndexMCPy": 19, "riIndexPIPy": 20, "riIndexDIPy": 1, "riMiddleMCPy": 21,
                   "riMiddlePIPy": 25, "riMiddleDIPy": 3, "riRingMCPy": 21, "riRingPIPy": 25,
                   "riRingDIPy": 3, "riPinkyMCPy": 15, "riPinkyPIPy": 18, "riPinkyDIPy": 12},
    (0.0, 0.0): {"riWristFlexion": 22, "riThumbCMCz": 34},
    (0.0, 90.0): {"riWristDeviation": -29, "riThumbCMCy": 40, "riThumbMCPz": 38,
                  "riThumbIPz": 26},
}


def _synthetic(n_inc: int = 7, n_rot: int = 12) -> tuple[SagGrid, np.ndarray, np.ndarray]:
    """A grid whose DOF k is a + b*inc + c*cos(rot): bilinear-checkable, poles flat."""
    inc = np.linspace(-90, 90, n_inc)
    rot = -180 + 360 / n_rot * np.arange(n_rot)
    ii, rr = np.meshgrid(inc, rot, indexing="ij")
    k = np.arange(23)
    vals = k + 0.1 * k * ii[..., None] + np.cos(np.radians(ii))[..., None] * np.sin(
        np.radians(rr))[..., None] * (k + 1)
    return SagGrid(ii, rr, vals, np.arange(23.0)), ii, vals


def test_lookup_hits_samples_and_interpolates_bilinearly() -> None:
    g, _, vals = _synthetic()
    np.testing.assert_allclose(g.lookup(-30.0, 0.0), vals[2, 6], atol=1e-12)
    np.testing.assert_allclose(g.lookup(0.0, 90.0), vals[3, 9], atol=1e-12)
    # midway between four samples: the mean of the corners
    mid = g.lookup(-15.0, 15.0)
    np.testing.assert_allclose(mid, vals[2:4, 6:8].mean(axis=(0, 1)), atol=1e-12)
    # a quarter of the way in inclination, on a rotation sample: linear in inclination
    np.testing.assert_allclose(g.lookup(-22.5, 30.0), 0.75 * vals[2, 7] + 0.25 * vals[3, 7])


def test_lookup_on_non_uniform_axes_uses_the_actual_spacing() -> None:
    inc = np.array([-90.0, -30.0, 0.0, 1.0, 2.0, 90.0])
    rot = np.array([-180.0, -179.0, -178.0, 0.0, 178.0, 179.0])
    ii, rr = np.meshgrid(inc, rot, indexing="ij")
    rng = np.random.default_rng(1)
    vals = rng.uniform(-10, 10, (6, 6, 23))
    vals[0], vals[-1] = vals[0, 0], vals[-1, 0]  # poles flat
    g = SagGrid(ii, rr, vals, np.zeros(23))
    np.testing.assert_allclose(g.lookup(0.5, -179.5), vals[2:4, :2].mean(axis=(0, 1)))
    # a quarter of the way across the 60-degree cell, and of the 178-degree one
    np.testing.assert_allclose(g.lookup(-75.0, -178.0), 0.75 * vals[0, 2] + 0.25 * vals[1, 2])
    np.testing.assert_allclose(g.lookup(1.0, -133.5), 0.75 * vals[3, 2] + 0.25 * vals[3, 3])
    # across the seam: 179 -> 180 (= -180) is 1 degree wide
    np.testing.assert_allclose(g.lookup(2.0, 179.5), 0.5 * (vals[4, 5] + vals[4, 0]))


def test_rotation_wraps_around() -> None:
    g, _, vals = _synthetic()
    np.testing.assert_allclose(g.lookup(30.0, 180.0), vals[4, 0], atol=1e-12)
    np.testing.assert_allclose(g.lookup(30.0, -180.0), g.lookup(30.0, 540.0), atol=1e-12)
    # across the seam, between rotation 150 (last column) and 180 (= -180, first)
    np.testing.assert_allclose(g.lookup(30.0, 165.0), 0.5 * (vals[4, -1] + vals[4, 0]))
    np.testing.assert_allclose(g.lookup(10.0, -200.0), g.lookup(10.0, 160.0), atol=1e-12)


def test_vertical_does_not_depend_on_rotation() -> None:
    g, _, vals = _synthetic()
    for rot in (-180.0, -37.0, 0.0, 91.0, 179.9):
        np.testing.assert_allclose(g.lookup(90.0, rot), vals[-1, 0], atol=1e-12)
        np.testing.assert_allclose(g.lookup(-90.0, rot), vals[0, 0], atol=1e-12)


def test_offsets_are_values_minus_rest_and_out_is_reused() -> None:
    g, _, _ = _synthetic()
    out = np.empty(23)
    res = g.offsets(12.0, -33.0, out=out)
    assert res is out
    np.testing.assert_allclose(out, g.lookup(12.0, -33.0) - g.rest_deg, atol=1e-12)
    g.lookup(1.0, 2.0, out=out)
    g.lookup(1.0, 2.0)
    tracemalloc.start()
    peaks = {}
    for label, target in (("out", out), ("new", None)):
        current = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        g.lookup(12.0, -33.0, out=target)
        peaks[label] = tracemalloc.get_traced_memory()[1] - current
    tracemalloc.stop()
    assert peaks["new"] >= 23 * 8  # a fresh result array is visible to tracemalloc...
    assert peaks["out"] < 23 * 8  # ...and with out= there is none (a few Python floats)


def test_left_hand_view_shares_the_table() -> None:
    g, _, _ = _synthetic()
    le = g.for_hand("le")
    assert le.dof_names == DOF_NAMES["le"] and g.dof_names == DOF_NAMES["ri"]
    np.testing.assert_array_equal(le.lookup(20.0, 70.0), g.lookup(20.0, 70.0))


def test_bad_input_is_a_clear_error(tmp_path: Path) -> None:
    g, ii, vals = _synthetic()
    with pytest.raises(DataError, match="NaN"):
        g.lookup(float("nan"), 0.0)
    with pytest.raises(DataError, match="outside"):
        g.lookup(95.0, 0.0)
    with pytest.raises(DataError, match="not finite"):
        g.lookup(0.0, float("inf"))
    rr = -180 + 30.0 * np.arange(12)
    bent = np.meshgrid(ii[:, 0], rr, indexing="ij")[1].copy()
    bent[3, 4] += 1.0
    with pytest.raises(DataError, match="rectilinear"):
        SagGrid(ii, bent, vals, np.zeros(23))
    tilted = vals.copy()
    tilted[-1, 5] += 1.0
    with pytest.raises(DataError, match="must not depend on rotation"):
        SagGrid(ii, np.meshgrid(ii[:, 0], rr, indexing="ij")[1], tilted, np.zeros(23))
    with pytest.raises(DataError, match="not found"):
        SagGrid.load(tmp_path / "missing.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(DataError, match="not a readable"):
        SagGrid.load(tmp_path / "junk.npz")


@pytest.fixture(scope="module")
def shipped() -> SagGrid:
    return SagGrid.load()


def test_shipped_grid_reproduces_table2_at_the_calibration_orientations(
    shipped: SagGrid,
) -> None:
    assert shipped.source == str(SAG_GRID)
    for (inc, rot), expect in CALIBRATED.items():
        values = dict(zip(shipped.dof_names, shipped.lookup(inc, rot), strict=True))
        for name, v in expect.items():
            assert values[name] == pytest.approx(v, abs=1.0), (inc, rot, name)


def test_shipped_grid_sags_the_physical_way(shipped: SagGrid) -> None:
    names = shipped.dof_names
    mcp = [names.index(f"ri{f}MCPy") for f in ("Index", "Middle", "Ring", "Pinky")]
    down = shipped.offsets(0.0, 0.0)
    up = shipped.offsets(0.0, 180.0)
    hang = shipped.offsets(-90.0, 0.0)
    assert np.all(down[mcp] > 0) and np.all(up[mcp] < 0) and np.all(hang[mcp] < 0)
    assert down[names.index("riWristFlexion")] > 0 > up[names.index("riWristFlexion")]
    assert shipped.offsets(0.0, 90.0)[names.index("riWristDeviation")] < 0


def test_shipped_grid_stays_inside_the_joint_ranges(shipped: SagGrid) -> None:
    lim = dof_limits_deg("ri")
    assert np.all(shipped.dofs_deg >= lim[:, 0]) and np.all(shipped.dofs_deg <= lim[:, 1])
    meta = shipped.metadata
    for key in ("step_deg", "hand_length_m", "model_sha256", "ks_nm_per_rad", "rest_deg"):
        assert key in meta
    np.testing.assert_array_equal(shipped.rest_deg,
                                  [meta["rest_deg"][n] for n in DOF_NAMES["ri"]])


def test_runtime_modules_do_not_import_mujoco() -> None:
    import subprocess
    import sys

    code = ("import sys, handrig.pose.sag, handrig.pose.orientation;"
            " print(sorted(m for m in ('mujoco', 'sim') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]"
