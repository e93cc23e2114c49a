"""The reduced hand at runtime: one frame of controls -> two full hands (50 curves)."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from handrig.offline import mocap
from handrig.pose.expand import DEFAULT_TWO_GLOVE_MAP, Expander
from handrig.pose.maps import LinearMap


def _measure(ex: Expander, frames: int = 20000, inputs: np.ndarray | None = None
             ) -> tuple[float, float]:
    if inputs is None:
        rng = np.random.default_rng(0)
        inputs = ex.control_means_deg + rng.normal(0.0, 10.0, size=(frames, len(ex.controls)))
    inputs = np.resize(inputs, (frames, inputs.shape[1]))
    out = np.empty(len(ex.curve_names))
    times = np.empty(frames)
    for row in inputs[:1000]:
        ex.expand(row, out=out)
    clock = time.perf_counter_ns
    for i in range(frames):
        row = inputs[i]
        t0 = clock()
        ex.expand(row, out=out)
        times[i] = clock() - t0
    return float(np.median(times)) / 1e3, float(np.percentile(times, 99)) / 1e3


def main() -> None:
    for label, path in (("right glove, 5 controls", None),
                        ("two gloves, 10 controls", DEFAULT_TWO_GLOVE_MAP)):
        ex = Expander.from_file(path)
        med, p99 = _measure(ex)
        print(f"expand one frame, two hands (50 curves), {label}: median {med:.2f} us,"
              f" p99 {p99:.2f} us (target: median <= 10 us)")
    lm = LinearMap.load(DEFAULT_TWO_GLOVE_MAP)
    with_range, without = Expander(lm), Expander(replace(lm, control_range_deg=None))
    ref = mocap.load_reference().curves[:, lm.control_indices]
    a_med, _ = _measure(with_range, inputs=ref)
    b_med, _ = _measure(without, inputs=ref)
    print(f"training-range count (two gloves, the reference capture's controls replayed):"
          f" median {a_med:.2f} us with it, {b_med:.2f} us for the same map without a"
          f" recorded range; {with_range.training_range().summary()}")
    far = np.tile(lm.control_means_deg + 50.0, (100, 1))
    c_med, _ = _measure(with_range, inputs=far)
    print(f"  every control outside its range: median {c_med:.2f} us")
    ex = Expander.from_file()
    batch = np.tile(ex.control_means_deg, (10000, 1))
    out = np.empty((10000, 50))
    t0 = time.perf_counter()
    for _ in range(20):
        ex.expand_many(batch, out=out)
    per = (time.perf_counter() - t0) / (20 * 10000) * 1e9
    print(f"expand_many, 10000 frames per call: {per:.0f} ns per frame")
