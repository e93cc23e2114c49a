"""Baking: static solve vs dynamic settle, file format, shipped grid vs model."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from handrig.errors import DataError
from handrig.hand import DOF_NAMES
from handrig.pose.sag import SagGrid
from sim import bake
from sim.hand_model import hand_geometry
from sim.passive import PassiveHand, load_passive_params


@pytest.fixture(scope="module")
def coarse() -> bake.BakedGrid:
    return bake.bake_static(step_deg=30.0)


def test_axes_and_step_validation() -> None:
    inc, rot = bake.grid_axes(5.0)
    assert (len(inc), len(rot)) == (37, 72)
    assert inc[0] == -90 and inc[-1] == 90 and rot[0] == -180 and rot[-1] == 175
    for bad in (7.0, 0.1, 60.0):
        with pytest.raises(DataError, match="divides 90"):
            bake.grid_axes(bad)
    with pytest.raises(DataError, match="fine step"):
        bake.grid_axes(5.0, 5.0)


def test_fine_band_refines_palm_up_and_keeps_the_rest() -> None:
    inc, rot = bake.grid_axes(2.5, 1.0)
    assert (len(inc), len(rot)) == (100, 240)
    assert inc[0] == -90 and inc[-1] == 90 and rot[0] == -180 and rot[-1] == 179
    assert np.all(np.diff(inc) > 0) and np.all(np.diff(rot) > 0)
    d_inc = np.diff(inc)
    band = (inc[:-1] >= 0) & (inc[1:] <= 45)
    assert np.allclose(d_inc[band], 1.0) and np.allclose(d_inc[~band], 2.5)
    ends = np.append(rot, 180.0)
    start, end, d_rot = ends[:-1], ends[1:], np.diff(ends)
    fine = (end <= -100 + 1e-9) | (start >= 100 - 1e-9)
    assert fine.sum() == 160
    assert np.allclose(d_rot[fine], 1.0) and np.allclose(d_rot[~fine], 2.5)


def test_static_bake_is_stable_and_agrees_with_the_dynamic_settle(
    coarse: bake.BakedGrid,
) -> None:
    meta = coarse.metadata
    assert meta["unstable_samples"] == 0 and meta["max_residual_nm"] < 1e-8
    ref = bake.bake_dynamic(step_deg=30.0, vel_tol_deg_s=0.001)
    assert ref.metadata["capped_samples"] == 0
    cmp = bake.compare(coarse, ref)  # every sample, the whole sphere
    assert float(cmp["max_deg"]) < 0.05, cmp
    assert float(cmp["median_deg"]) < 0.01


def test_saved_grid_loads_for_lookup(coarse: bake.BakedGrid, tmp_path: Path) -> None:
    path = coarse.save(tmp_path / "g")
    assert path.suffix == ".npz"
    grid = SagGrid.load(path)
    np.testing.assert_allclose(grid.lookup(0.0, 0.0), coarse.dofs_deg[3, 6], atol=1e-4)
    assert grid.metadata["solver"] == "static-newton"
    assert grid.metadata["step_deg"] == 30.0
    png = bake.plot(coarse, tmp_path / "g.png")
    assert png.stat().st_size > 10_000


def test_shipped_grid_is_baked_from_the_shipped_model() -> None:
    cfg = load_passive_params()
    grid = SagGrid.load()
    assert grid.metadata["config_inputs_sha256"] == cfg.inputs_sha256()
    assert grid.metadata["model_sha256"] == bake.model_hash(cfg), "re-run `handrig bake`"


def test_lookups_between_samples_match_a_direct_solve() -> None:
    grid = SagGrid.load()
    ph = PassiveHand(load_passive_params())
    rng = np.random.default_rng(7)
    # the whole sphere, plus extra draws in the palm-up band where the pose bends fastest
    orientations = [(rng.uniform(-90, 90), rng.uniform(-180, 180)) for _ in range(60)]
    orientations += [(rng.uniform(0, 60), rng.choice([-1, 1]) * rng.uniform(100, 180))
                     for _ in range(40)]
    errors = []
    for inc, rot in orientations:
        looked = grid.lookup(inc, rot)
        direct = ph.solve_static(inc, rot, looked).q_deg
        # a cold start (from the rest pose) finds the same pose: one equilibrium
        np.testing.assert_allclose(ph.solve_static(inc, rot).q_deg, direct, atol=1e-3)
        direct = np.clip(direct, grid.limits_deg[:, 0], grid.limits_deg[:, 1])
        errors.append(np.abs(looked - direct).max())
    assert max(errors) < 0.5
    assert np.median(errors) < 0.05


def _finger_com_angle_deg(q_deg: NDArray[np.float64], finger: str) -> float:
    """Angle of the finger's centre of mass about its MCP, from the palm plane toward the
    palm (degrees): the finger's flexion as a whole."""
    names = DOF_NAMES["ri"]
    x = z = a = mx = mz = 0.0
    for seg, joint in zip(hand_geometry().segments[finger], ("MCPy", "PIPy", "DIPy"),
                          strict=True):
        a += math.radians(q_deg[names.index(f"ri{finger}{joint}")])
        mx += seg.mass_kg * (x + 0.5 * seg.length_m * math.cos(a))
        mz += seg.mass_kg * (z + 0.5 * seg.length_m * math.sin(a))
        x += seg.length_m * math.cos(a)
        z += seg.length_m * math.sin(a)
    return math.degrees(math.atan2(mz, mx))


def test_palm_down_flexes_and_palm_up_extends_the_fingers() -> None:
    """"The fingers flex" = each finger as a whole turns toward the palm: its MCP flexes and
    its centre of mass swings palmar about the knuckle. Palm down, PIP and DIP open a
    little (sim/passive.py: the distal phalanges hang past the vertical there, whatever
    the stiffness); palm up with the forearm horizontal every finger joint extends."""
    grid = SagGrid.load()
    names = DOF_NAMES["ri"]
    for inc in (0.0, 30.0):
        down, up = grid.lookup(inc, 0.0), grid.lookup(inc, 180.0)
        for f in ("Index", "Middle", "Ring", "Pinky"):
            mcp = names.index(f"ri{f}MCPy")
            assert down[mcp] > grid.rest_deg[mcp] + 5.0, (inc, f)
            assert up[mcp] < grid.rest_deg[mcp] - 5.0, (inc, f)
            rest_com = _finger_com_angle_deg(grid.rest_deg, f)
            assert _finger_com_angle_deg(down, f) > rest_com + 2.0, (inc, f)
            assert _finger_com_angle_deg(up, f) < rest_com - 2.0, (inc, f)
            if inc == 0.0:
                for joint in ("PIPy", "DIPy"):
                    i = names.index(f"ri{f}{joint}")
                    assert up[i] < grid.rest_deg[i] - 5.0, (f, joint)


def test_palm_down_distal_phalanges_hang_past_vertical() -> None:
    """Why palm down cannot flex the DIPs: at the palm-down equilibrium each distal phalanx
    points past straight down (wrist + MCP + PIP + DIP > 90 deg from the forearm axis), so
    gravity turns it back toward the vertical, i.e. extends the DIP; flexing it further
    would only add to that angle."""
    ph = PassiveHand(load_passive_params())
    names = DOF_NAMES["ri"]
    q = ph.solve_static(0.0, 0.0).q_deg
    torque = ph.gravity_torque(q)
    for f in ("Index", "Middle", "Ring", "Pinky"):
        chain = ("riWristFlexion", f"ri{f}MCPy", f"ri{f}PIPy", f"ri{f}DIPy")
        assert sum(q[names.index(n)] for n in chain) > 100.0, f
        dip = names.index(f"ri{f}DIPy")
        assert torque[dip] < 0 and q[dip] < ph.rest_deg[dip], f
