"""Bake the sag grid: the relaxed hand's 23 DOFs over forearm inclination x rotation.

The paper (section 4.1) samples by simulating the arm through every orientation.
Here the default is the **static equilibrium** of the same model (Newton on
ks (rest - q) + limits + gravity torque = 0, :meth:`sim.passive.PassiveHand.solve_static`),
warm-started from the neighbouring sample, with a stability check (all eigenvalues
of the residual's Jacobian negative) at every sample. The **dynamic settle sweep**
(:func:`bake_dynamic`: integrate from the neighbouring sample until every joint is
slower than 0.01 deg/s) is kept as the reference; :func:`compare` reports how far
they differ (``bench/bench_sag.py`` prints both).

Grid: inclination from -90 (hanging down) to +90 (pointing up) inclusive, rotation
from -180 to 180 - step (anatomical: 0 palm down, +90 thumb up, 180 palm up, the
same for both hands; it wraps). ``fine_step_deg`` refines a band (palm up, forearm
0..45 deg up: :data:`FINE_BAND_INCLINATION_DEG`, :data:`FINE_BAND_ROTATION_DEG`)
where the pose bends fastest with orientation; the axes stay rectilinear. The
shipped grid is step 2.5 with 1 deg in the band (100 x 240 samples). The model has
one stable equilibrium per orientation (sim/passive.py, "Raised hand"), so the
static solve, the dynamic settle and a cold solve from the rest pose agree
everywhere. The rows at +-90 do not depend on rotation (gravity along the forearm);
they are solved once and copied, so the singularity is exact.
Gravity is set exactly (``opt.gravity``), so the stored "actual" coordinates equal
the nominal ones; they are stored anyway, as the paper does.

File (``.npz``): ``inclination_deg`` (n_inc, n_rot), ``rotation_deg`` (n_inc, n_rot),
``dofs_deg`` (n_inc, n_rot, 23; float32, 1e-5 deg is plenty) in vocabulary order and
convention, ``dof_names`` (23,), ``rest_deg`` (23,), ``limits_deg`` (23, 2),
``metadata`` (a JSON string: model parameters, gains, hand length, step, model hash,
solver statistics).
"""

from __future__ import annotations

import dataclasses
import gc
import hashlib
import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from handrig.errors import DataError
from handrig.hand import DOF_NAMES, dof_limits_deg
from sim.hand_model import hand_model_xml
from sim.passive import PassiveHand
from sim.passive_config import PassiveHandConfig, load_passive_params

Progress = Callable[[int, int], None]
GRID_FORMAT = 1


@dataclasses.dataclass
class BakedGrid:
    """A baked grid in memory (see the module docstring for the file layout)."""

    inclination_deg: NDArray[np.float64]
    rotation_deg: NDArray[np.float64]
    dofs_deg: NDArray[np.float64]
    rest_deg: NDArray[np.float64]
    limits_deg: NDArray[np.float64]
    metadata: dict[str, Any]

    def save(self, path: str | Path) -> Path:
        """Write the grid as ``.npz`` (the extension is added if missing)."""
        p = Path(path)
        if p.suffix != ".npz":
            p = p.with_suffix(".npz")
        p.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(
            p, inclination_deg=self.inclination_deg, rotation_deg=self.rotation_deg,
            dofs_deg=self.dofs_deg.astype(np.float32), dof_names=np.array(DOF_NAMES["ri"]),
            rest_deg=self.rest_deg, limits_deg=self.limits_deg,
            metadata=np.array(json.dumps(self.metadata, sort_keys=True)),
        )
        return p


# Where the shipped grid is refined (``fine_step_deg``): palm up (|rotation| >= 100) with
# the forearm between horizontal and 45 deg up. There the curled fingers' distal phalanges
# point upward and the hand is least stiff against gravity (sim/passive.py, "Raised
# hand"), so the equilibrium bends fastest with orientation; at 2.5 deg a bilinear
# lookup there missed a direct solve by up to 1.2 deg, elsewhere by at most 0.15 deg.
FINE_BAND_INCLINATION_DEG = (0.0, 45.0)
FINE_BAND_ROTATION_DEG = 100.0


def _refine(axis: NDArray[np.float64], lo: float, hi: float,
            fine_step_deg: float) -> NDArray[np.float64]:
    """``axis`` with the samples between ``lo`` and ``hi`` (widened to the nearest axis
    samples) replaced by evenly spaced ones at most ``fine_step_deg`` apart."""
    a = float(axis[axis <= lo + 1e-9].max()) if np.any(axis <= lo + 1e-9) else float(axis[0])
    b = float(axis[axis >= hi - 1e-9].min()) if np.any(axis >= hi - 1e-9) else float(axis[-1])
    n = math.ceil((b - a) / fine_step_deg - 1e-9) + 1
    return np.concatenate([axis[axis < a - 1e-9], np.linspace(a, b, n), axis[axis > b + 1e-9]])


def grid_axes(
    step_deg: float, fine_step_deg: float | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Inclination (-90..90 inclusive) and rotation (-180..180-step) sample axes.

    ``fine_step_deg`` (smaller than ``step_deg``): sample the band
    :data:`FINE_BAND_INCLINATION_DEG` x (|rotation| >= :data:`FINE_BAND_ROTATION_DEG`)
    at most that far apart (the axes stay rectilinear, so the fine rows and columns run
    across the whole grid)."""
    if not (0.5 <= step_deg <= 45.0) or abs(90.0 / step_deg - round(90.0 / step_deg)) > 1e-9:
        raise DataError(
            f"step {step_deg} deg: use a step between 0.5 and 45 deg that divides 90"
            " (e.g. 2, 5, 10, 15)")
    n_inc = round(180.0 / step_deg) + 1
    n_rot = round(360.0 / step_deg)
    incs = np.linspace(-90.0, 90.0, n_inc)
    rots = -180.0 + step_deg * np.arange(n_rot + 1, dtype=np.float64)  # up to +180
    if fine_step_deg is not None:
        if not 0.1 <= fine_step_deg < step_deg:
            raise DataError(f"fine step {fine_step_deg} deg: use 0.1 deg or more and less"
                            f" than the step ({step_deg} deg)")
        incs = _refine(incs, *FINE_BAND_INCLINATION_DEG, fine_step_deg)
        rots = _refine(rots, -180.0, -FINE_BAND_ROTATION_DEG, fine_step_deg)
        rots = _refine(rots, FINE_BAND_ROTATION_DEG, 180.0, fine_step_deg)
    return incs, rots[:-1]


def model_hash(cfg: PassiveHandConfig) -> str:
    """sha256 of the exact MJCF the grid was baked from."""
    xml = hand_model_xml("ri", cfg.hand_length_m, passive=cfg.springs(), mujoco_limits=False)
    return hashlib.sha256(xml.encode()).hexdigest()


def _metadata(cfg: PassiveHandConfig, step_deg: float, fine_step_deg: float | None,
              solver: str, stats: dict[str, Any]) -> dict[str, Any]:
    springs = cfg.springs()
    fine: dict[str, Any] = {}
    if fine_step_deg is not None:
        fine = {"fine_step_deg": fine_step_deg,
                "fine_band": {"inclination_deg": list(FINE_BAND_INCLINATION_DEG),
                              "abs_rotation_min_deg": FINE_BAND_ROTATION_DEG}}
    return {
        "format": GRID_FORMAT, "solver": solver, "step_deg": step_deg, **fine,
        "raised_stiffness_factor": cfg.raised_stiffness_factor,
        "hand_length_m": cfg.hand_length_m, "model_sha256": model_hash(cfg),
        "config_inputs_sha256": cfg.inputs_sha256(),
        "limit_gain_factor": cfg.limit_gain_factor,
        "ks_nm_per_rad": dict(springs.ks_nm_per_rad),
        "kd_nms_per_rad": dict(springs.kd_nms_per_rad),
        "kd_per_ks_s": dict(cfg.tuned.kd_per_ks_s) if cfg.tuned else {},
        "rest_deg": dict(cfg.rest_deg),
        "convention": "degrees; flexion positive; abduction/deviation radial positive;"
                      " rotation 0 palm down, +90 thumb up, 180 palm up (both hands)",
        **stats,
    }


def clip_to_limits(dofs_deg: NDArray[np.float64]) -> float:
    """Clip (..., 23) values into the joint ranges in place; returns the largest overshoot.

    The paper's limit terms (equations 2-3) are stiff springs, so an equilibrium can sit
    slightly past a limit (about 0.5 deg at limit_gain_factor 20); the grid stores values
    inside the range, which is what the pose pipeline and the servos accept."""
    lim = dof_limits_deg("ri")
    over = np.maximum(lim[:, 0] - dofs_deg, 0.0) + np.maximum(dofs_deg - lim[:, 1], 0.0)
    np.clip(dofs_deg, lim[:, 0], lim[:, 1], out=dofs_deg)
    return float(over.max()) if over.size else 0.0


def bake_static(
    cfg: PassiveHandConfig | None = None,
    step_deg: float = 5.0,
    *,
    fine_step_deg: float | None = None,
    progress: Progress | None = None,
) -> BakedGrid:
    """Bake by static equilibrium solves (the default; see the module docstring).
    ``fine_step_deg``: refine the band of :func:`grid_axes`."""
    cfg = cfg if cfg is not None else load_passive_params()
    ph = PassiveHand(cfg)
    incs, rots = grid_axes(step_deg, fine_step_deg)
    n_inc, n_rot = len(incs), len(rots)
    out = np.empty((n_inc, n_rot, 23))
    t0 = time.perf_counter()
    iters, worst_res, worst_eig, unstable, retried = 0, 0.0, -math.inf, 0, 0
    bottom = ph.solve_static(-90.0, 0.0)
    top = ph.solve_static(90.0, 0.0, bottom.q_deg)
    for j, rot in enumerate(rots):
        out[0, j] = bottom.q_deg
        out[-1, j] = top.q_deg
        q = bottom.q_deg
        for i in range(1, n_inc - 1):
            sol = ph.solve_static(float(incs[i]), float(rot), q)
            if not sol.stable or sol.residual_nm > 1e-8:
                # retry from the neighbouring column's sample, then from the rest pose
                retried += 1
                starts = ([out[i, j - 1]] if j > 0 else []) + [None]
                for start in starts:
                    alt = ph.solve_static(float(incs[i]), float(rot), start)
                    if alt.stable and alt.residual_nm <= 1e-8:
                        sol = alt
                        break
            unstable += int(not sol.stable)
            iters += sol.iterations
            worst_res = max(worst_res, sol.residual_nm)
            worst_eig = max(worst_eig, sol.max_eigenvalue)
            out[i, j] = q = sol.q_deg
        if progress is not None:
            progress(j + 1, n_rot)
    elapsed = time.perf_counter() - t0
    inc_grid, rot_grid = np.meshgrid(incs, rots, indexing="ij")
    stats = {"seconds": elapsed, "newton_iterations_mean": iters / max(1, (n_inc - 2) * n_rot),
             "max_residual_nm": worst_res, "max_jacobian_eigenvalue": worst_eig,
             "unstable_samples": unstable, "retried_samples": retried}
    stats["max_limit_overshoot_deg"] = clip_to_limits(out)
    return BakedGrid(inc_grid, rot_grid, out, ph.rest_deg.copy(), dof_limits_deg("ri"),
                     _metadata(cfg, step_deg, fine_step_deg, "static-newton", stats))


def bake_dynamic(
    cfg: PassiveHandConfig | None = None,
    step_deg: float = 5.0,
    *,
    fine_step_deg: float | None = None,
    vel_tol_deg_s: float = 0.01,
    max_s: float = 30.0,
    progress: Progress | None = None,
) -> BakedGrid:
    """The reference: per sample, integrate from the previous sample's pose until every
    joint moves slower than ``vel_tol_deg_s`` (columns swept from hanging down upward), at
    most ``max_s`` simulated seconds per sample (palm up the slowest mode takes about 8 s
    to get below 0.001 deg/s from 30 deg away); samples that hit it are counted."""
    cfg = cfg if cfg is not None else load_passive_params()
    ph = PassiveHand(cfg)
    incs, rots = grid_axes(step_deg, fine_step_deg)
    n_inc, n_rot = len(incs), len(rots)
    out = np.empty((n_inc, n_rot, 23))
    t0 = time.perf_counter()
    sim_s, capped = 0.0, 0
    bottom, t = ph.settle(-90.0, 0.0, vel_tol_deg_s=vel_tol_deg_s, max_s=max_s)
    sim_s += t
    top, t = ph.settle(90.0, 0.0, bottom, vel_tol_deg_s=vel_tol_deg_s, max_s=max_s)
    sim_s += t
    for j, rot in enumerate(rots):
        out[0, j], out[-1, j] = bottom, top
        q = bottom
        for i in range(1, n_inc - 1):
            q, t = ph.settle(float(incs[i]), float(rot), q, vel_tol_deg_s=vel_tol_deg_s,
                             max_s=max_s)
            sim_s += t
            capped += int(t >= max_s - 1e-6)
            out[i, j] = q
        if progress is not None:
            progress(j + 1, n_rot)
    elapsed = time.perf_counter() - t0
    inc_grid, rot_grid = np.meshgrid(incs, rots, indexing="ij")
    stats = {"seconds": elapsed, "simulated_s": sim_s, "vel_tol_deg_s": vel_tol_deg_s,
             "max_s": max_s, "capped_samples": capped}
    stats["max_limit_overshoot_deg"] = clip_to_limits(out)
    return BakedGrid(inc_grid, rot_grid, out, ph.rest_deg.copy(), dof_limits_deg("ri"),
                     _metadata(cfg, step_deg, fine_step_deg, "dynamic-settle", stats))


def compare(a: BakedGrid, b: BakedGrid) -> dict[str, float | str]:
    """Max and median absolute difference (degrees) between two grids of the same shape."""
    if a.dofs_deg.shape != b.dofs_deg.shape:
        raise DataError(f"grids differ in shape: {a.dofs_deg.shape} vs {b.dofs_deg.shape}")
    diff = np.abs(a.dofs_deg - b.dofs_deg)
    worst = np.unravel_index(int(np.argmax(diff)), diff.shape)
    return {"max_deg": float(diff.max()), "median_deg": float(np.median(diff)),
            "p99_deg": float(np.percentile(diff, 99)),
            "worst_inclination_deg": float(a.inclination_deg[worst[0], worst[1]]),
            "worst_rotation_deg": float(a.rotation_deg[worst[0], worst[1]]),
            "worst_dof": DOF_NAMES["ri"][int(worst[2])]}


def plot(grid: BakedGrid, path: str | Path) -> Path:
    """Draw every DOF over inclination x rotation (a 5 x 5 sheet of heat maps, PNG).

    Leaves no process state behind: no pyplot figure, no backend switch, and the
    figure's reference cycles are collected before returning. Left to the cycle
    collector, they (about 90 000 objects) were freed by whichever ``gc.collect()``
    ran next, e.g. the rig's before its loop: 0.1 s without goals, which trips the
    servos' 100 ms Bus Watchdog, after which they refuse every goal.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    _draw_sheet(grid, p)
    gc.collect()
    return p


def _draw_sheet(grid: BakedGrid, path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(20, 17), layout="constrained")
    inc = grid.inclination_deg[:, 0]
    rot = grid.rotation_deg[0, :]
    for k, ax in enumerate(fig.subplots(5, 5).flat):
        if k >= 23:
            ax.axis("off")
            continue
        # pcolormesh: the axes may be non-uniform (a refined band)
        img = ax.pcolormesh(rot, inc, grid.dofs_deg[:, :, k], shading="nearest",
                            cmap="viridis", rasterized=True)
        ax.set_title(f"{DOF_NAMES['ri'][k]} (rest {grid.rest_deg[k]:g})", fontsize=9)
        ax.set_xticks([-180, -90, 0, 90])
        ax.set_yticks([-90, -45, 0, 45, 90])
        fig.colorbar(img, ax=ax, shrink=0.8, label="deg")
        if k % 5 == 0:
            ax.set_ylabel("inclination (deg)")
        if k >= 18:
            ax.set_xlabel("rotation (deg): 0 palm down, 90 thumb up")
    meta = grid.metadata
    fine = (f", {meta['fine_step_deg']} deg in the palm-up band" if meta.get("fine_step_deg")
            else "")
    fig.suptitle(f"Relaxed-hand sag grid ({meta.get('solver')}, step {meta.get('step_deg')} deg"
                 f"{fine}, hand length {meta.get('hand_length_m')} m, {len(inc)} x {len(rot)})")
    fig.savefig(path, dpi=55)
