"""The compiled realtime kernels against plain numpy written from the same definitions."""

from __future__ import annotations

import copy

import numpy as np

from handrig import kernels
from handrig.app import build_parts
from handrig.filters import OneEuroFilter


def test_servo_targets_kernel_matches_the_numpy_step() -> None:
    pipeline = build_parts().pipeline
    reference = copy.deepcopy(pipeline)
    rng = np.random.default_rng(7)
    n_controls = len(pipeline.expander.controls)
    for k in range(1500):
        controls = rng.uniform(-30, 100, n_controls)
        if k % 37 == 0:
            controls[rng.integers(n_controls)] = np.nan if k % 2 else np.inf
        inc, rot = rng.uniform(-90, 90), rng.uniform(-540, 540)
        dt = rng.choice([0.005, 0.0, 0.05])
        got = pipeline.servo_targets(controls, inc, rot, dt).copy()
        want = reference._servo_targets_numpy(controls, inc, rot, dt)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
        np.testing.assert_allclose(pipeline._raw_targets, reference._raw_targets, atol=1e-9)
    assert pipeline.rejected == reference.rejected > 0


def test_goal_body_clamps_holds_and_encodes_ticks() -> None:
    rng = np.random.default_rng(3)
    n = 20
    low, high = rng.uniform(-40, 0, n), rng.uniform(10, 90, n)
    tpd = rng.choice([-1, 1], n) * rng.uniform(4, 30, n)
    zero = rng.uniform(1000, 3000, n)
    last = np.full(n, np.nan)
    hold = np.clip(0.0, low, high)
    body = np.zeros((n, 5), np.uint8)
    body[:, 0] = np.arange(1, n + 1)
    for _ in range(300):
        goals = rng.uniform(-120, 150, n)
        goals[rng.integers(n)] = rng.choice([np.nan, np.inf, -np.inf])
        out = np.zeros(n)
        changed = kernels.goal_body(goals, low, high, last, hold, tpd, zero, out, body)
        want = np.clip(goals, low, high)
        bad = ~np.isfinite(goals)
        want[bad] = np.where(np.isnan(last), hold, last)[bad]
        assert changed == np.count_nonzero(want != goals)
        np.testing.assert_array_equal(out, want)
        ticks = np.clip(np.rint(want * tpd + zero), 0, 4095).astype("<i4")
        assert body[:, 1:].tobytes() == ticks.view(np.uint8).reshape(n, 4).tobytes()
        assert body[:, 0].tolist() == list(range(1, n + 1))  # IDs untouched
        last = out.copy()


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


def test_fast_sync_decode_reads_signed_fields_in_any_order() -> None:
    rng = np.random.default_rng(9)
    n = 7
    order = rng.permutation(n)
    zero, tpd = rng.uniform(1000, 3000, n), rng.choice([-1, 1], n) * rng.uniform(5, 20, n)
    dps, ma = rng.uniform(0.1, 2, n), rng.uniform(0.5, 3, n)
    for read_len in (4, 10):
        cur = rng.integers(-2000, 2000, n).astype("<i2")
        vel = rng.integers(-400, 400, n).astype("<i4")
        pos = rng.integers(-5000, 9000, n).astype("<i4")
        errs = rng.choice([0, 0x80], n).astype(np.uint8)
        blocks = []
        for i in range(n):
            data = pos[i].tobytes() if read_len == 4 else (
                cur[i].tobytes() + vel[i].tobytes() + pos[i].tobytes())
            blocks.append(bytes((errs[i], 1 + order[i])) + data + b"\0\0")
        raw = np.frombuffer(bytes(8) + b"".join(blocks), np.uint8)
        out = [np.full(n, np.nan) for _ in range(3)]
        status = np.zeros(n, np.uint8)
        alerts = kernels.fast_sync_decode(raw, read_len, order, zero, tpd, dps, ma, *out,
                                          status)
        assert alerts == np.count_nonzero(errs)
        np.testing.assert_allclose(out[0][order], (pos - zero[order]) / tpd[order])
        np.testing.assert_array_equal(status[order], errs)
        if read_len == 10:
            np.testing.assert_allclose(out[1][order], vel * dps[order])
            np.testing.assert_allclose(out[2][order], cur * ma[order])
        bad = raw.copy()
        bad[8 + 3 * (read_len + 4)] = 0x02  # an error number: nothing is written
        before = [o.copy() for o in out]
        assert kernels.fast_sync_decode(bad, read_len, order, zero, tpd, dps, ma, *out,
                                        status) == -1
        for o, b in zip(out, before, strict=True):
            np.testing.assert_array_equal(o, b)
