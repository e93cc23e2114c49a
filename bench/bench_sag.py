"""Sag grid: bake time at 5 deg steps (static solve; dynamic settle sweep beside it) and
the runtime lookup (orientation -> 23 values), median over many calls."""

from __future__ import annotations

import os
import statistics
import time

import numpy as np

from handrig.pose.orientation import ForearmOrientation
from handrig.pose.sag import SagGrid


def _median_us(fn: object, calls: int = 2000, batches: int = 25) -> float:
    per_call = []
    for _ in range(batches):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()  # type: ignore[operator]
        per_call.append((time.perf_counter() - t0) / calls * 1e6)
    return statistics.median(per_call)


def _accuracy(grid: SagGrid, n: int = 400) -> None:
    """Shipped grid vs a direct static solve (warm-started at the lookup; a cold solve from
    the rest pose must find the same pose) at random orientations over the whole sphere."""
    from sim.passive import PassiveHand, load_passive_params

    ph = PassiveHand(load_passive_params())
    rng = np.random.default_rng(11)
    err = np.empty(n)
    cold_apart = 0
    for k in range(n):
        inc, rot = float(rng.uniform(-90, 90)), float(rng.uniform(-180, 180))
        looked = grid.lookup(inc, rot)
        direct = ph.solve_static(inc, rot, looked).q_deg
        cold_apart += int(np.abs(ph.solve_static(inc, rot).q_deg - direct).max() > 1e-3)
        direct = np.clip(direct, grid.limits_deg[:, 0], grid.limits_deg[:, 1])
        err[k] = np.abs(looked - direct).max()
    n_inc, n_rot = grid.dofs_deg.shape[:2]
    meta = grid.metadata
    fine = f", {meta['fine_step_deg']} deg palm-up band" if meta.get("fine_step_deg") else ""
    print(f"shipped grid ({meta.get('step_deg')} deg{fine}; {n_inc} x {n_rot}) vs direct"
          f" solve, {n} random orientations (whole sphere), worst DOF each: median"
          f" {np.median(err):.4f} deg, p95 {np.percentile(err, 95):.3f}, max {err.max():.3f};"
          f" > 0.5 deg: {(err > 0.5).sum()}; cold solve elsewhere: {cold_apart}")


def main() -> None:
    from sim import bake

    t0 = time.perf_counter()
    static = bake.bake_static(step_deg=5.0)
    static_s = time.perf_counter() - t0
    n_inc, n_rot = static.dofs_deg.shape[:2]
    print(f"bake, static Newton, 5 deg ({n_inc} x {n_rot}): {static_s:.2f} s"
          f" (limit 10 s; {static.metadata['newton_iterations_mean']:.2f} iterations/sample,"
          f" unstable {static.metadata['unstable_samples']})")
    if os.environ.get("HANDRIG_BENCH_QUICK"):
        print("dynamic settle sweep: skipped (HANDRIG_BENCH_QUICK set)")
    else:
        t0 = time.perf_counter()
        dyn = bake.bake_dynamic(step_deg=5.0)
        dyn_s = time.perf_counter() - t0
        cmp = bake.compare(static, dyn)
        print(f"bake, dynamic settle sweep, same grid: {dyn_s:.1f} s"
              f" ({dyn.metadata['simulated_s']:.0f} s simulated, settle to"
              f" {dyn.metadata['vel_tol_deg_s']} deg/s, {dyn.metadata['capped_samples']}"
              f" samples hit the {dyn.metadata['max_s']:g} s cap)")
        print(f"static vs dynamic: median {cmp['median_deg']:.1e} deg, p99"
              f" {cmp['p99_deg']:.3f} deg, max {cmp['max_deg']:.3f} deg (at inclination"
              f" {cmp['worst_inclination_deg']:g}, rotation {cmp['worst_rotation_deg']:g},"
              f" {cmp['worst_dof']})")
    grid = SagGrid.load()
    _accuracy(grid)
    out = np.empty(23)
    rng = np.random.default_rng(0)
    pts = [(float(a), float(b)) for a, b in zip(rng.uniform(-90, 90, 64),
                                                  rng.uniform(-180, 180, 64), strict=True)]
    k = [0]

    def lookup() -> None:
        a, b = pts[k[0] & 63]
        k[0] += 1
        grid.offsets(a, b, out=out)

    print(f"lookup (inclination, rotation) -> 23 offsets, out=: {_median_us(lookup):.2f} us"
          " median (limit 10 us)")
    fo = ForearmOrientation()
    quats = [list(fo.quaternion_for(a, b, 30.0)) for a, b in pts]

    def full() -> None:
        q = quats[k[0] & 63]
        k[0] += 1
        a, b = fo.angles(q)
        grid.offsets(a, b, out=out)

    print(f"IMU quaternion -> angles -> 23 offsets: {_median_us(full):.2f} us median")
