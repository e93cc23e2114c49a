"""Compiled kernels for the realtime path (numba), from a glove frame to the Sync Write.

Why compiled: the loop runs once every 5 ms and sleeps in between, so each cycle
starts with cold CPU caches. Measured on the 2-core VM this project is built on,
after a 4 ms pause the numpy version of the servo targets alone took 42 us (92 us
after a sleep) against 11 us back to back: a dozen small numpy calls each walk a
large amount of cold dispatch code. One compiled loop over the 20 servos (targets,
sag, limits, slew, ticks and packet bytes together) took 5 us (11 us after a sleep).

Each kernel is a plain loop that the numpy code it replaces could be checked
against: ``tests/handrig/test_kernels.py`` does, on random inputs including NaN
and inf. ``cache=True`` keeps the machine code in ``__pycache__``; :func:`warm_up`
compiles (or loads) everything before a loop starts, never inside a cycle.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

POSITION_TICKS_MAX = 4095  # X-series Goal Position in position control mode


@njit(cache=True, nogil=True)
def _sag_cell(axis: Any, x: float) -> int:  # pragma: no cover - compiled
    """Index i of the cell [axis[i], axis[i + 1]] holding x (the last cell past the end)."""
    i = int(np.searchsorted(axis, x, side="right")) - 1
    last = axis.shape[0] - 2
    if i > last:
        i = last
    if i < 0:
        i = 0
    return i


@njit(cache=True, nogil=True)
def servo_targets(
    controls: Any, a: Any, b: Any, inc_axis: Any, rot_axis: Any, rot0: float, cells: Any,
    slot: Any, gain: float, inclination: float, rotation: float, low: Any, high: Any,
    targets: Any, limit: float, first: bool, raw: Any,
) -> int:  # pragma: no cover - compiled
    """The servo targets in place: ``targets`` (n,) becomes the slew-limited step toward
    ``controls @ a + b + gain * sag[slot]``, clamped to ``[low, high]``.

    ``cells`` (n_inc-1, n_rot-1, 4, n_dof): each grid cell's four corner offsets
    (:class:`handrig.sag.SagGrid`); ``slot[k] >= n_dof`` means no sag for servo k;
    an empty ``cells`` means no sag at all. ``inclination`` is already checked and
    clamped to -90..90, ``rotation`` finite. A non-finite target holds the previous
    one (the middle of the range on the first step); returns how many did.
    ``raw`` gets the targets before slew limiting. ``first``: no previous targets yet.
    """
    n = targets.shape[0]
    n_dof = cells.shape[3]
    use_sag = cells.shape[0] > 0
    w0 = w1 = w2 = w3 = 0.0
    i = j = 0
    if use_sag:
        i = _sag_cell(inc_axis, inclination)
        r = (rotation - rot0) % 360.0 + rot0
        j = _sag_cell(rot_axis, r)
        ti = (inclination - inc_axis[i]) / (inc_axis[i + 1] - inc_axis[i])
        tj = (r - rot_axis[j]) / (rot_axis[j + 1] - rot_axis[j])
        w0 = (1.0 - ti) * (1.0 - tj)
        w1 = (1.0 - ti) * tj
        w2 = ti * (1.0 - tj)
        w3 = ti * tj
    held = 0
    for k in range(n):
        v = b[k]
        for m in range(controls.shape[0]):
            v += controls[m] * a[m, k]
        s = slot[k]
        if use_sag and s < n_dof:
            v += gain * (w0 * cells[i, j, 0, s] + w1 * cells[i, j, 1, s]
                         + w2 * cells[i, j, 2, s] + w3 * cells[i, j, 3, s])
        if not math.isfinite(v):
            held += 1
            v = 0.5 * (low[k] + high[k]) if first else targets[k]
        v = min(max(v, low[k]), high[k])
        raw[k] = v
        if first:
            targets[k] = v
        else:
            step = min(max(v - targets[k], -limit), limit)
            targets[k] = targets[k] + step
    return held


def _crc_table() -> np.ndarray:
    """The byte table of the Dynamixel Protocol 2.0 CRC-16 (poly 0x8005, init 0, not
    reflected), as in the e-manual and dynamixel-sdk's ``updateCRC``."""
    table = np.zeros(256, np.uint16)
    for i in range(256):
        crc = i << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else crc << 1
        table[i] = crc & 0xFFFF
    return table


CRC_TABLE = _crc_table()
SYNC_WRITE_BODY = 12  # header 4, ID, LEN 2, instruction, address 2, data length 2


@njit(cache=True, nogil=True)
def crc16(data: Any, stop: int) -> int:  # pragma: no cover - compiled
    """The Protocol 2.0 CRC of ``data[:stop]`` (uint8); checked against dynamixel-sdk's
    ``updateCRC`` by the driver at start and by the tests."""
    crc = 0
    for i in range(stop):
        crc = ((crc << 8) ^ CRC_TABLE[((crc >> 8) ^ data[i]) & 0xFF]) & 0xFFFF
    return crc


@njit(cache=True, nogil=True)
def goal_packet(
    goals: Any, low: Any, high: Any, last: Any, hold: Any, ticks_per_deg: Any,
    zero_ticks: Any, goal_out: Any, packet: Any,
) -> int:  # pragma: no cover - compiled
    """Goals clamped into ``goal_out`` and written as Goal Position ticks into the goal
    Sync Write ``packet`` (uint8, whole packet), whose CRC is then recomputed. The
    packet's first ``SYNC_WRITE_BODY`` bytes and each block's ID byte are left alone;
    bytes 1-4 of block ``k`` get servo ``k``'s little-endian position. A non-finite
    goal becomes the last goal sent, or ``hold`` before any. Returns how many goals
    were changed."""
    changed = 0
    for k in range(goals.shape[0]):
        g = goals[k]
        if math.isfinite(g):
            v = min(max(g, low[k]), high[k])
            if v != g:
                changed += 1
        else:
            changed += 1
            v = last[k] if math.isfinite(last[k]) else hold[k]
        goal_out[k] = v
        t = int(np.rint(v * ticks_per_deg[k] + zero_ticks[k]))
        t = min(max(t, 0), POSITION_TICKS_MAX)
        b = SYNC_WRITE_BODY + 5 * k
        packet[b + 1] = t & 0xFF
        packet[b + 2] = (t >> 8) & 0xFF
        packet[b + 3] = 0
        packet[b + 4] = 0
    end = packet.shape[0] - 2
    crc = crc16(packet, end)
    packet[end] = crc & 0xFF
    packet[end + 1] = crc >> 8
    return changed


@njit(cache=True, nogil=True)
def calibrate(
    raw: Any, raw_index: Any, gain: Any, offset: Any, lo: Any, hi: Any, last_good: Any,
    out: Any,
) -> int:  # pragma: no cover - compiled
    """Raw counts -> degrees (``raw[raw_index] * gain + offset``, clamped to
    ``[lo, hi]``) into ``out``; a non-finite reading holds ``last_good`` (which the
    finite ones update). ``raw`` must be long enough (checked by the caller).
    Returns how many readings were held."""
    held = 0
    for k in range(out.shape[0]):
        v = raw[raw_index[k]] * gain[k] + offset[k]
        if not math.isfinite(v):
            held += 1
            v = last_good[k]
        v = min(max(v, lo[k]), hi[k])
        last_good[k] = v
        out[k] = v
    return held


@njit(cache=True, nogil=True)
def one_euro_step(
    x: Any, te: float, x_hat: Any, dx_hat: Any, min_cutoff: Any, beta: Any, two_pi_d: Any,
) -> None:  # pragma: no cover - compiled
    """One step of the One Euro filter (handrig.filters) over every channel, in place on
    ``x_hat`` and ``dx_hat``; ``te`` > 0 is the time since the previous sample."""
    two_pi_te = 2.0 * math.pi * te
    for i in range(x.shape[0]):
        prev = x_hat[i]
        a_d = 1.0 / (1.0 + 1.0 / (two_pi_d[i] * te))
        d = dx_hat[i] + a_d * ((x[i] - prev) / te - dx_hat[i])
        dx_hat[i] = d
        fc = min_cutoff[i] + beta[i] * abs(d)
        x_hat[i] = prev + (x[i] - prev) / (1.0 + 1.0 / (two_pi_te * fc))


@njit(cache=True, nogil=True)
def glove_controls(
    raw: Any, raw_index: Any, gain: Any, offset: Any, lo: Any, hi: Any, last_good: Any,
    deg: Any, filtered: bool, prime: bool, te: float, x_hat: Any, dx_hat: Any,
    min_cutoff: Any, beta: Any, two_pi_d: Any, perm: Any, out: Any,
) -> int:  # pragma: no cover - compiled
    """:func:`calibrate`, then (``filtered``) the One Euro filter (``prime``: the first
    sample passes through; a step only when ``te`` > 0), then ``out = deg[perm]``.
    Returns how many readings were held."""
    held = calibrate(raw, raw_index, gain, offset, lo, hi, last_good, deg)
    if filtered:
        if prime:
            for i in range(deg.shape[0]):
                x_hat[i] = deg[i]
        elif te > 0.0:
            one_euro_step(deg, te, x_hat, dx_hat, min_cutoff, beta, two_pi_d)
        for i in range(deg.shape[0]):
            deg[i] = x_hat[i]
    for i in range(out.shape[0]):
        out[i] = deg[perm[i]]
    return held


NOT_THIS_REPLY = -3  # fast_sync_whole: wrong length, header or servo order
BAD_CRC = -2  # fast_sync_whole: the CRC over the whole reply fails
ERROR_NUMBER = -1  # fast_sync_whole: some servo answered with an error number


@njit(cache=True, nogil=True)
def fast_sync_whole(
    raw: Any, read_len: int, order: Any, ids: Any, scale: Any, latest: Any,
    status_err: Any, stale_run: Any, fresh: Any, now: float, out: Any, out_u8: Any,
) -> int:  # pragma: no cover - compiled
    """Take a Fast Sync Read reply to a request for every servo, checked and decoded
    in one pass, in place of several small steps each costing microseconds in a cold
    cache after the wait.

    ``raw``: the reply (uint8). Block ``i`` must name ``ids[i]`` and carry servo
    ``order[i]`` (rig index); ``read_len`` is 4 (Present Position) or 10 (Present
    Current, Velocity, Position). ``scale`` rows: zero ticks, ticks per joint degree,
    joint deg/s per velocity unit, mA per current unit. ``latest`` rows: the
    driver's readings (position, velocity, current, temperature, time read).

    Returns ``NOT_THIS_REPLY`` or ``BAD_CRC`` (nothing written) when the reply is not
    intact as a whole, ``ERROR_NUMBER`` (nothing written) when a servo reports an
    error number (ERR & 0x7F); otherwise stores every reading, ERR byte and
    ``fresh`` and returns how many servos raise the Alert bit (0x80). When none
    does, the read is complete: the readings' time becomes ``now``, ``stale_run``
    0, and the new state is written out: ``out`` rows position, velocity, current,
    temperature, age (0); ``out_u8`` rows status error, hardware error (0),
    stale (0)."""
    n = order.shape[0]
    block = read_len + 4
    total = 8 + block * n
    if raw.shape[0] != total:
        return NOT_THIS_REPLY
    length = total - 7
    if (raw[0] != 0xFF or raw[1] != 0xFF or raw[2] != 0xFD or raw[3] != 0 or raw[4] != 0xFE
            or raw[5] != (length & 0xFF) or raw[6] != (length >> 8) or raw[7] != 0x55):
        return NOT_THIS_REPLY
    for i in range(n):
        if raw[9 + i * block] != ids[i]:
            return NOT_THIS_REPLY
    crc = crc16(raw, total - 2)
    if crc != (raw[total - 2] | (raw[total - 1] << 8)):
        return BAD_CRC
    alerts = 0
    for i in range(n):
        err = raw[8 + i * block]
        if err & 0x7F:
            return ERROR_NUMBER
        if err & 0x80:
            alerts += 1
    for i in range(n):
        b = 8 + i * block
        k = order[i]
        status_err[k] = raw[b]
        fresh[k] = True
        d = b + 2
        if read_len == 10:
            cur = raw[d] | (raw[d + 1] << 8)
            if cur >= 0x8000:
                cur -= 0x10000
            vel = raw[d + 2] | (raw[d + 3] << 8) | (raw[d + 4] << 16) | (raw[d + 5] << 24)
            if vel >= 0x80000000:
                vel -= 0x100000000
            latest[2, k] = cur * scale[3, k]
            latest[1, k] = vel * scale[2, k]
            d += 6
        pos = raw[d] | (raw[d + 1] << 8) | (raw[d + 2] << 16) | (raw[d + 3] << 24)
        if pos >= 0x80000000:
            pos -= 0x100000000
        latest[0, k] = (pos - scale[0, k]) / scale[1, k]
    if alerts == 0:
        for k in range(latest.shape[1]):
            latest[4, k] = now
            stale_run[k] = 0
            for r in range(4):
                out[r, k] = latest[r, k]
            out[4, k] = 0.0
            out_u8[0, k] = status_err[k]
            out_u8[1, k] = 0
            out_u8[2, k] = 0
    return alerts


def warm_up() -> None:
    """Compile (or load from the cache) every kernel with the types the loop uses."""
    f = np.zeros(2)
    servo_targets(f, np.zeros((2, 2)), f, np.array([0.0, 1.0]), np.array([0.0, 1.0]), 0.0,
                  np.zeros((1, 1, 4, 2)), np.zeros(2, np.int64), 1.0, 0.5, 0.5, f - 1.0,
                  f + 1.0, np.zeros(2), 1.0, False, np.zeros(2))
    goal_packet(f, f - 1.0, f + 1.0, f, f, f + 1.0, f, np.zeros(2),
                np.zeros(SYNC_WRITE_BODY + 12, np.uint8))
    idx = np.zeros(2, np.intp)
    for read_len in (4, 10):
        reply = np.frombuffer(bytes(8 + 2 * (read_len + 4)), np.uint8)  # read-only, as used
        fast_sync_whole(reply, read_len, idx,
                        np.zeros(2, np.uint8), np.ones((4, 2)), np.zeros((5, 2)),
                        np.zeros(2, np.uint8), np.zeros(2, np.int64), np.zeros(2, np.bool_),
                        0.0, np.zeros((5, 2)), np.zeros((3, 2), np.uint8))
    one_euro_step(f, 0.01, np.zeros(2), np.zeros(2), f + 1.0, f, f + 1.0)
    glove_controls(f, idx, f + 1.0, f, f - 1.0, f + 1.0, np.zeros(2), np.zeros(2), True,
                   False, 0.01, np.zeros(2), np.zeros(2), f + 1.0, f, f + 1.0, idx, np.zeros(2))
