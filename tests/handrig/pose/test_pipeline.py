"""The pose pipeline's servo step (the compiled kernel) against a numpy reference written
from its definition."""

from __future__ import annotations

import math

import numpy as np

from handrig.app.parts import build_parts
from handrig.pose.pipeline import ServoPath
from handrig.pose.sag import SagGrid


class NumpyServoStep:
    """:meth:`PosePipeline.servo_targets` in plain numpy: ``clip(features @ a + b,
    map_low, map_high) + gain * offsets[slot]`` (offsets looked up with
    :meth:`SagGrid.offsets`, not the kernel's tables), a non-finite target holds the
    previous one, clamp, slew limit. The features are the controls, then (a
    piecewise-linear map) ``max(0, controls - knots)``."""

    def __init__(self, path: ServoPath, sag: SagGrid | None, low: np.ndarray,
                 high: np.ndarray, slew_deg_s: float) -> None:
        self.path, self.sag, self.low, self.high = path, sag, low, high
        self.slew_deg_s = slew_deg_s
        self.targets: np.ndarray | None = None
        self.raw = np.zeros(len(low))
        self.rejected = 0

    def __call__(self, controls: np.ndarray, inc: float, rot: float, dt: float) -> np.ndarray:
        path = self.path
        with np.errstate(invalid="ignore"):  # inf - inf: a NaN the step must hold
            h = len(path.knots)  # a piecewise-linear map: the controls' hinges follow them
            features = np.concatenate([controls, np.maximum(controls[:h] - path.knots, 0.0)])
            raw = features @ path.a + path.b
            raw = np.where(np.isfinite(raw), np.clip(raw, path.map_low, path.map_high), raw)
            if self.sag is not None:
                offsets = np.append(self.sag.offsets(inc, rot), 0.0)  # slot 23: no sag
                raw = raw + path.sag_gain * offsets[np.minimum(path.sag_slot, 23)]
            total = raw.sum()
        if not math.isfinite(total):
            bad = ~np.isfinite(raw)
            self.rejected += int(bad.sum())
            fallback = self.targets if self.targets is not None else 0.5 * (
                self.low + self.high)
            raw = np.where(bad, fallback, raw)
        raw = np.clip(raw, self.low, self.high)
        self.raw = raw
        if self.targets is None:
            self.targets = raw.copy()
        else:
            limit = self.slew_deg_s * max(dt, 0.0)
            self.targets = self.targets + np.clip(raw - self.targets, -limit, limit)
        return self.targets


def test_servo_targets_kernel_matches_the_numpy_reference() -> None:
    parts = build_parts()
    pipeline = parts.pipeline
    reference = NumpyServoStep(pipeline.servo_path, parts.sag, pipeline.servo_low,
                               pipeline.servo_high, pipeline.slew_deg_s)
    rng = np.random.default_rng(7)
    n_controls = len(pipeline.expander.controls)
    for k in range(1500):
        controls = rng.uniform(-30, 100, n_controls)
        if k % 37 == 0:
            controls[rng.integers(n_controls)] = np.nan if k % 2 else np.inf
        inc, rot = rng.uniform(-90, 90), rng.uniform(-540, 540)
        dt = rng.choice([0.005, 0.0, 0.05])
        got = pipeline.servo_targets(controls, inc, rot, dt).copy()
        want = reference(controls, inc, rot, dt)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
        np.testing.assert_allclose(pipeline.raw_targets, reference.raw, atol=1e-9)
    assert pipeline.rejected == reference.rejected > 0


def test_relaxed_targets_are_the_clamped_relaxed_pose() -> None:
    pl = build_parts().pipeline
    want_pose = np.clip(pl.relaxed_pose(30.0, 90.0), pl.pose_low, pl.pose_high)
    got = pl.relaxed_targets(30.0, 90.0)
    np.testing.assert_allclose(pl.relaxed, want_pose)
    np.testing.assert_allclose(
        got, np.clip(want_pose[pl.servo_index], pl.servo_low, pl.servo_high))
