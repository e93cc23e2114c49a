"""The compiled pose kernels against plain numpy written from the same definitions
(the servo-target step's reference is in test_pipeline.py)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from handrig.pose import kernels
from handrig.pose.filters import OneEuroFilter


def test_calibrate_and_filter_kernel_matches_numpy() -> None:
    rng = np.random.default_rng(5)
    k = 4
    idx = np.array([2, 0, 3, 1], np.intp)
    gain, offset = rng.uniform(-0.1, 0.1, k), rng.uniform(-20, 20, k)
    lo, hi = np.full(k, -30.0), np.full(k, 90.0)
    last_good = np.zeros(k)
    flt = OneEuroFilter(k, min_cutoff_hz=1.5, beta=0.02, d_cutoff_hz=1.0)
    x_hat, dx_hat = np.zeros(k), np.zeros(k)
    ref_last = last_good.copy()
    perm = np.array([3, 1, 0, 2], np.intp)
    deg, out = np.zeros(k), np.zeros(k)
    t = 0.0
    for step in range(400):
        raw = rng.uniform(0, 4095, 5)
        if step % 50 == 7:
            raw[idx[1]] = np.nan
        te = 0.005 if step else 0.0
        t += te
        held = kernels.glove_controls(raw, idx, gain, offset, lo, hi, last_good, deg, True,
                                      step == 0, te, x_hat, dx_hat, flt.min_cutoff_hz,
                                      flt.beta, flt._two_pi_d, perm, out)
        v = raw[idx] * gain + offset
        bad = ~np.isfinite(v)
        v[bad] = ref_last[bad]
        v = np.clip(v, lo, hi)
        ref_last = v.copy()
        want = flt.filter(v, t)[perm]
        assert held == bad.sum()
        np.testing.assert_allclose(out, want, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(last_good, ref_last)


def test_the_pose_pipeline_imports_no_wire_code() -> None:
    code = ("import sys, handrig.pose.pipeline, handrig.devices.glove_calibration, "
            "handrig.pose.filters; "
            "print(sorted(m for m in sys.modules if m.startswith(('handrig.devices.servo', "
            "'dynamixel_sdk', 'serial'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"
