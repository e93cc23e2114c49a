"""Baking: static solve vs dynamic settle, file format, shipped grid vs model."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from handrig.errors import DataError
from handrig.hand import DOF_NAMES
from handrig.sag import SagGrid
from sim import bake
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


def test_static_bake_is_stable_and_agrees_with_the_dynamic_settle(
    coarse: bake.BakedGrid,
) -> None:
    meta = coarse.metadata
    assert meta["unstable_samples"] == 0 and meta["max_residual_nm"] < 1e-8
    ref = bake.bake_dynamic(step_deg=30.0, vel_tol_deg_s=0.001)
    # outside the raised palm-up band where the fingers have two stable equilibria
    smooth = coarse.inclination_deg < 30.0
    diff = np.abs(coarse.dofs_deg - ref.dofs_deg)[smooth]
    assert diff.max() < 0.05
    cmp = bake.compare(coarse, ref)
    assert cmp["median_deg"] < 0.01


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
    errors = []
    for _ in range(60):
        inc, rot = rng.uniform(-90, 25), rng.uniform(-180, 180)  # below the bistable band
        looked = grid.lookup(inc, rot)
        direct = ph.solve_static(inc, rot, looked).q_deg
        direct = np.clip(direct, grid.limits_deg[:, 0], grid.limits_deg[:, 1])
        errors.append(np.abs(looked - direct).max())
    assert max(errors) < 0.5
    assert np.median(errors) < 0.05


def test_palm_down_flexes_and_palm_up_extends_the_fingers() -> None:
    grid = SagGrid.load()
    names = DOF_NAMES["ri"]
    mcp = [names.index(f"ri{f}MCPy") for f in ("Index", "Middle", "Ring", "Pinky")]
    for inc in (0.0, 30.0):
        assert np.all(grid.offsets(inc, 0.0)[mcp] > 0)
        assert np.all(grid.offsets(inc, 180.0)[mcp] < 0)
