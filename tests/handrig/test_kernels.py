"""The compiled realtime kernels against plain numpy written from the same definitions."""

from __future__ import annotations

import numpy as np

from handrig import kernels
from handrig.filters import OneEuroFilter
from handrig.servo.packets import sdk_crc16


def test_kernel_crc_is_the_sdk_crc() -> None:
    rng = np.random.default_rng(1)
    for n in (0, 1, 2, 9, 116, 168, 600):
        data = rng.integers(0, 256, n, dtype=np.uint8)
        assert kernels.crc16(data, n) == sdk_crc16(data.tobytes())
        assert kernels.crc16(data, n // 2) == sdk_crc16(data[: n // 2].tobytes())


def test_goal_packet_clamps_holds_encodes_ticks_and_crc() -> None:
    rng = np.random.default_rng(3)
    n = 20
    low, high = rng.uniform(-40, 0, n), rng.uniform(10, 90, n)
    tpd = rng.choice([-1, 1], n) * rng.uniform(4, 30, n)
    zero = rng.uniform(1000, 3000, n)
    last = np.full(n, np.nan)
    hold = np.clip(0.0, low, high)
    prefix = b"\xff\xff\xfd\x00\xfe" + (5 * n + 7).to_bytes(2, "little") + b"\x83\x74\x00\x04\x00"
    packet = np.zeros(kernels.SYNC_WRITE_BODY + 5 * n + 2, np.uint8)
    packet[:12] = np.frombuffer(prefix, np.uint8)
    packet[12::5][:n] = np.arange(1, n + 1)
    for _ in range(300):
        goals = rng.uniform(-120, 150, n)
        goals[rng.integers(n)] = rng.choice([np.nan, np.inf, -np.inf])
        out = np.zeros(n)
        changed = kernels.goal_packet(goals, low, high, last, hold, tpd, zero, out, packet)
        want = np.clip(goals, low, high)
        bad = ~np.isfinite(goals)
        want[bad] = np.where(np.isnan(last), hold, last)[bad]
        assert changed == np.count_nonzero(want != goals)
        np.testing.assert_array_equal(out, want)
        ticks = np.clip(np.rint(want * tpd + zero), 0, 4095).astype("<i4")
        blocks = b"".join(bytes((i + 1,)) + ticks[i].tobytes() for i in range(n))
        body = prefix + blocks
        crc = sdk_crc16(body)
        assert packet.tobytes() == body + bytes((crc & 0xFF, crc >> 8))
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


def _fast_sync_reply(blocks: list[tuple[int, int, bytes]]) -> np.ndarray:
    """A Fast Sync Read reply: header, then [ERR, ID, data, running CRC] per servo."""
    total = 8 + sum(4 + len(d) for _, _, d in blocks)
    raw = bytearray(b"\xff\xff\xfd\x00\xfe" + (total - 7).to_bytes(2, "little") + b"\x55")
    for err, sid, data in blocks:
        raw += bytes((err, sid)) + data
        crc = sdk_crc16(raw)
        raw += bytes((crc & 0xFF, crc >> 8))
    return np.frombuffer(bytes(raw), np.uint8)


def test_fast_sync_whole_checks_and_decodes_signed_fields_in_any_order() -> None:
    rng = np.random.default_rng(9)
    n = 7
    order = rng.permutation(n)
    ids = (10 + order).astype(np.uint8)  # servo k has ID 10 + k
    scale = np.stack([rng.uniform(1000, 3000, n), rng.choice([-1, 1], n) * rng.uniform(5, 20, n),
                      rng.uniform(0.1, 2, n), rng.uniform(0.5, 3, n)])
    zero, tpd, dps, ma = scale
    for read_len in (4, 10):
        for alerting in (False, True):
            cur = rng.integers(-2000, 2000, n).astype("<i2")
            vel = rng.integers(-400, 400, n).astype("<i4")
            pos = rng.integers(-5000, 9000, n).astype("<i4")
            errs = np.zeros(n, np.uint8)
            if alerting:
                errs[rng.integers(n)] = 0x80
            raw = _fast_sync_reply([
                (int(errs[i]), int(ids[i]), pos[i].tobytes() if read_len == 4
                 else cur[i].tobytes() + vel[i].tobytes() + pos[i].tobytes())
                for i in range(n)])
            latest = np.full((5, n), np.nan)
            latest[3] = rng.uniform(20, 40, n)  # temperatures: kept, copied into the state
            status = np.zeros(n, np.uint8)
            stale_run = np.full(n, 3, np.int64)
            fresh = np.zeros(n, bool)
            out, out_u8 = np.full((5, n), -1.0), np.full((3, n), 7, np.uint8)
            args = (read_len, order, ids, scale, latest, status, stale_run, fresh, 12.5, out,
                    out_u8)
            alerts = kernels.fast_sync_whole(raw, *args)
            assert alerts == np.count_nonzero(errs)
            np.testing.assert_allclose(latest[0, order], (pos - zero[order]) / tpd[order])
            np.testing.assert_array_equal(status[order], errs)
            assert fresh.all()
            if read_len == 10:
                np.testing.assert_allclose(latest[1, order], vel * dps[order])
                np.testing.assert_allclose(latest[2, order], cur * ma[order])
            else:
                assert np.isnan(latest[1:3]).all()
            if alerting:  # not a whole read: the caller handles the alert, no state written
                assert (out == -1.0).all() and (out_u8 == 7).all() and (stale_run == 3).all()
                assert np.isnan(latest[4]).all()
            else:
                np.testing.assert_array_equal(out[:4], latest[:4])
                assert (out[4] == 0).all() and (latest[4] == 12.5).all()
                np.testing.assert_array_equal(out_u8[0], status)
                assert (out_u8[1:] == 0).all() and (stale_run == 0).all()

            # damaged replies write nothing
            flipped = raw.copy()
            flipped[9 + 2 * (read_len + 4) + 1] ^= 0x40  # a data bit: the CRC fails
            reordered = _fast_sync_reply([(0, int(ids[i]), bytes(read_len))
                                          for i in np.roll(np.arange(n), 1)])
            refusing = _fast_sync_reply([(0x02 if i == 3 else 0, int(ids[i]), bytes(read_len))
                                         for i in range(n)])
            fresh[:] = False
            touched = (latest, status, stale_run, fresh, out, out_u8)
            for bad, code in ((flipped, kernels.BAD_CRC), (raw[:-1], kernels.NOT_THIS_REPLY),
                              (reordered, kernels.NOT_THIS_REPLY),  # another read's order
                              (refusing, kernels.ERROR_NUMBER)):
                before = [a.copy() for a in touched]
                assert kernels.fast_sync_whole(bad, *args) == code
                for a, b in zip(touched, before, strict=True):
                    np.testing.assert_array_equal(a, b)
