"""Compiled kernels of the pose pipeline (numba): glove counts to joint degrees to servo targets.

Why compiled: the loop runs once a cycle and sleeps in between, so each cycle
starts with cold CPU caches, and a dozen small numpy calls each walk a large
amount of cold dispatch code; one compiled loop over the servos (targets, sag,
limits, slew) does the same work once.

Each kernel is a plain loop that the numpy code it replaces could be checked
against: ``tests/handrig/test_pose_kernels.py`` does, on random inputs including
NaN and inf. ``cache=True`` keeps the machine code in ``__pycache__``;
:func:`warm_up` compiles (or loads) everything before a loop starts, never inside
a cycle. No wire code here: the servo packets' kernels are in
:mod:`handrig.devices.servo.codec`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit


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
def _sag_weights(use_sag: bool, inc_axis: Any, rot_axis: Any, rot0: float,
                 inclination: float, rotation: float
                 ) -> tuple[int, int, float, float, float, float]:  # pragma: no cover
    """The grid cell (i, j) holding the forearm orientation and its four corners'
    bilinear weights (all zero without sag)."""
    if not use_sag:
        return 0, 0, 0.0, 0.0, 0.0, 0.0
    i = _sag_cell(inc_axis, inclination)
    r = (rotation - rot0) % 360.0 + rot0
    j = _sag_cell(rot_axis, r)
    ti = (inclination - inc_axis[i]) / (inc_axis[i + 1] - inc_axis[i])
    tj = (r - rot_axis[j]) / (rot_axis[j + 1] - rot_axis[j])
    return (i, j, (1.0 - ti) * (1.0 - tj), (1.0 - ti) * tj, ti * (1.0 - tj), ti * tj)


@njit(cache=True, nogil=True, inline="always")
def _hold_clamp_slew(k: int, v: float, low: Any, high: Any, targets: Any, first: bool,
                     limit: float, raw: Any) -> int:  # pragma: no cover - compiled
    """Servo ``k``'s new target ``v``: a non-finite one holds the previous target (the
    middle of the range on the first step), clamped to ``[low, high]`` into ``raw``,
    then slew limited into ``targets``; returns 1 if it was held."""
    held = 0
    if not math.isfinite(v):
        held = 1
        v = 0.5 * (low[k] + high[k]) if first else targets[k]
    v = min(max(v, low[k]), high[k])
    raw[k] = v
    if first:
        targets[k] = v
    else:
        step = min(max(v - targets[k], -limit), limit)
        targets[k] = targets[k] + step
    return held


@njit(cache=True, nogil=True)
def servo_targets(
    controls: Any, knots: Any, features: Any, a: Any, b: Any, inc_axis: Any, rot_axis: Any,
    rot0: float, cells: Any,
    slot: Any, gain: float, map_low: Any, map_high: Any, inclination: float,
    rotation: float, low: Any, high: Any, targets: Any, limit: float, first: bool, raw: Any,
) -> int:  # pragma: no cover - compiled
    """The servo targets in place: ``targets`` (n,) becomes the slew-limited step toward
    ``clip(features @ a + b, map_low, map_high) + gain * sag[slot]``, clamped to
    ``[low, high]`` (``map_low``/``map_high``: the map's output range, -inf/inf for none;
    a non-finite value stays non-finite). The features are the controls, then a
    piecewise-linear map's hinges ``max(0, controls[:h] - knots)`` (``knots`` (h,), empty
    for a linear map), written into ``features`` (k + h,) first (:func:`hinge_features`).

    ``cells`` (n_inc-1, n_rot-1, 4, n_dof): each grid cell's four corner offsets
    (:class:`handrig.pose.sag.SagGrid`); ``slot[k] >= n_dof`` means no sag for servo k;
    an empty ``cells`` means no sag at all. ``inclination`` is already checked and
    clamped to -90..90, ``rotation`` finite. A non-finite target holds the previous
    one (the middle of the range on the first step); returns how many did.
    ``raw`` gets the targets before slew limiting. ``first``: no previous targets yet.
    """
    n = targets.shape[0]
    n_dof = cells.shape[3]
    use_sag = cells.shape[0] > 0
    i, j, w0, w1, w2, w3 = _sag_weights(use_sag, inc_axis, rot_axis, rot0, inclination,
                                        rotation)
    x = controls
    if knots.shape[0] > 0:
        hinge_features(controls, knots, features)
        x = features
    held = 0
    for k in range(n):
        v = b[k]
        for m in range(x.shape[0]):
            v += x[m] * a[m, k]
        if math.isfinite(v):  # a non-finite value stays so: the step holds the target
            v = min(max(v, map_low[k]), map_high[k])
        s = slot[k]
        if use_sag and s < n_dof:
            v += gain * (w0 * cells[i, j, 0, s] + w1 * cells[i, j, 1, s]
                         + w2 * cells[i, j, 2, s] + w3 * cells[i, j, 3, s])
        held += _hold_clamp_slew(k, v, low, high, targets, first, limit, raw)
    return held


@njit(cache=True, nogil=True)
def robot_servo_targets(
    controls: Any, knots: Any, features: Any, a: Any, b: Any, inc_axis: Any, rot_axis: Any,
    rot0: float, cells: Any,
    slot: Any, gain: float, map_low: Any, map_high: Any, inclination: float,
    rotation: float, human_low: Any,
    human_high: Any, human: Any, g_start: Any, g_curve: Any, g_gain: Any, offset: Any,
    low: Any, high: Any, targets: Any, limit: float, first: bool, raw: Any,
) -> int:  # pragma: no cover - compiled
    """A robot hand's servo targets in place: the human curves it reads, then the
    retarget step, then the slew limit.

    ``human`` (u,) becomes ``clip(features @ a + b, map_low, map_high) + gain *
    sag[slot]`` (the ``u`` curves the retarget reads, as in :func:`servo_targets`, with its
    features, ``knots`` and ``features``), each
    clamped to
    ``[human_low, human_high]``; a non-finite curve stays non-finite. Then servo k's
    target is ``offset[k] + sum of g_gain[e] * human[g_curve[e]]`` over the entries
    ``e`` in ``g_start[k]:g_start[k + 1]`` (the table's nonzero gains, row by row, so a
    bad curve reaches only the joints that read it), clamped to
    ``[low, high]`` and slew limited as :func:`servo_targets` does; a non-finite target
    holds the previous one. Returns how many did.
    """
    n_dof = cells.shape[3]
    use_sag = cells.shape[0] > 0
    i, j, w0, w1, w2, w3 = _sag_weights(use_sag, inc_axis, rot_axis, rot0, inclination,
                                        rotation)
    x = controls
    if knots.shape[0] > 0:
        hinge_features(controls, knots, features)
        x = features
    for c in range(human.shape[0]):
        v = b[c]
        for m in range(x.shape[0]):
            v += x[m] * a[m, c]
        if math.isfinite(v):  # a non-finite value stays so: the step holds the target
            v = min(max(v, map_low[c]), map_high[c])
        s = slot[c]
        if use_sag and s < n_dof:
            v += gain * (w0 * cells[i, j, 0, s] + w1 * cells[i, j, 1, s]
                         + w2 * cells[i, j, 2, s] + w3 * cells[i, j, 3, s])
        if math.isfinite(v):
            v = min(max(v, human_low[c]), human_high[c])
        human[c] = v
    held = 0
    for k in range(targets.shape[0]):
        v = offset[k]
        for e in range(g_start[k], g_start[k + 1]):
            v += g_gain[e] * human[g_curve[e]]
        held += _hold_clamp_slew(k, v, low, high, targets, first, limit, raw)
    return held


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
    """One step of the One Euro filter (handrig.pose.filters) over every channel, in place on
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


@njit(cache=True, nogil=True)
def hinge_features(controls: Any, knots: Any, out: Any) -> None:  # pragma: no cover
    """A piecewise-linear map's features of one frame: ``out[:k] = controls`` and
    ``out[k + i] = max(0, controls[i] - knots[i])`` for the ``h`` knots (a non-finite
    control stays non-finite in both halves)."""
    k = controls.shape[0]
    for i in range(k):
        out[i] = controls[i]
    for i in range(knots.shape[0]):
        v = controls[i] - knots[i]
        out[k + i] = 0.0 if v <= 0.0 else v


@njit(cache=True, nogil=True)
def expand_frame(
    controls: Any, gains_t: Any, bias: Any, low: Any, high: Any, train_low: Any,
    train_high: Any, out: Any, outside_counts: Any,
) -> bool:  # pragma: no cover - compiled
    """One frame of the map: ``out = clip(bias + controls @ gains_t, low, high)``; each
    control below ``train_low`` or above ``train_high`` adds one to its
    ``outside_counts``. Returns whether any control was outside (NaN never is)."""
    k, m = gains_t.shape
    for j in range(m):
        out[j] = bias[j]
    for i in range(k):
        c = controls[i]
        for j in range(m):
            out[j] += c * gains_t[i, j]
    for j in range(m):
        v = out[j]
        if v < low[j]:
            out[j] = low[j]
        elif v > high[j]:
            out[j] = high[j]
    outside = False
    for i in range(k):
        c = controls[i]
        if c < train_low[i] or c > train_high[i]:
            outside_counts[i] += 1
            outside = True
    return outside


ANGLES_OK, ANGLES_REPAIRED, ANGLES_NONFINITE, ANGLES_BAD_NORM = 0, 1, 2, 3
"""What :func:`forearm_angles` says of the quaternion it was given."""


@njit(cache=True, nogil=True)
def forearm_angles(quat: Any, scalar_first: bool, up_sign: float, mount_t: Any,
                   sign_y: float, vertical_eps: float, min_norm: float, max_norm: float
                   ) -> tuple[float, float, int]:  # pragma: no cover - compiled
    """(inclination, rotation, status) in degrees of one IMU quaternion (4 components
    in the order ``scalar_first`` says): world up (z times ``up_sign``) in the IMU
    frame, into the forearm frame by ``mount_t`` (forearm <- IMU, 3x3), then
    ``atan2(up.x, hypot(y, z))`` and ``atan2(sign_y * up.y, up.z)`` (0 near vertical).
    Status: ANGLES_OK; ANGLES_REPAIRED (a norm off 1 by more than 1e-6, normalised);
    ANGLES_NONFINITE or ANGLES_BAD_NORM (outside ``[min_norm, max_norm]``): rejected,
    the angles are NaN. :meth:`handrig.pose.orientation.ForearmOrientation.angles` is the
    caller; its tests compare it with scipy's rotations."""
    a, b, c, d = quat[0], quat[1], quat[2], quat[3]
    if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(c) and math.isfinite(d)):
        return math.nan, math.nan, ANGLES_NONFINITE
    norm = math.sqrt(a * a + b * b + c * c + d * d)
    if not (min_norm <= norm <= max_norm):
        return math.nan, math.nan, ANGLES_BAD_NORM
    status = ANGLES_OK
    if abs(norm - 1.0) > 1e-6:
        status = ANGLES_REPAIRED
        a, b, c, d = a / norm, b / norm, c / norm, d / norm
    if scalar_first:
        w, x, y, z = a, b, c, d
    else:
        x, y, z, w = a, b, c, d
    # world up in the IMU frame: the world-z row of R_imu, negated for NED
    u0 = up_sign * 2.0 * (x * z - w * y)
    u1 = up_sign * 2.0 * (y * z + w * x)
    u2 = up_sign * (1.0 - 2.0 * (x * x + y * y))
    up0 = mount_t[0, 0] * u0 + mount_t[0, 1] * u1 + mount_t[0, 2] * u2
    up1 = mount_t[1, 0] * u0 + mount_t[1, 1] * u1 + mount_t[1, 2] * u2
    up2 = mount_t[2, 0] * u0 + mount_t[2, 1] * u1 + mount_t[2, 2] * u2
    py, pz = sign_y * up1, up2
    horizontal = math.hypot(py, pz)
    inc = math.degrees(math.atan2(up0, horizontal))
    rot = 0.0 if horizontal < vertical_eps else math.degrees(math.atan2(py, pz))
    return inc, rot, status


@njit(cache=True, nogil=True)
def _sag_into(pose: Any, idx: Any, absolute: bool, inc_axis: Any, rot_axis: Any, rot0: float,
              cells: Any, rest: Any, gain: float, inclination: float,
              rotation: float) -> None:  # pragma: no cover - compiled
    """One hand's sag at this forearm orientation into ``pose[idx]``: added to what is
    there (``absolute``: put on the rest pose instead)."""
    i, j, w0, w1, w2, w3 = _sag_weights(True, inc_axis, rot_axis, rot0, inclination, rotation)
    for d in range(idx.shape[0]):
        off = gain * (w0 * cells[i, j, 0, d] + w1 * cells[i, j, 1, d]
                      + w2 * cells[i, j, 2, d] + w3 * cells[i, j, 3, d])
        if absolute:
            pose[idx[d]] = rest[d] + off
        else:
            pose[idx[d]] += off


@njit(cache=True, nogil=True)
def pose_from_curves(
    curves: Any, mirror: bool, pose: Any, idx_a: Any, inc_a: float, rot_a: float, abs_a: bool,
    idx_b: Any, inc_b: float, rot_b: float, abs_b: bool, inc_axis: Any, rot_axis: Any,
    rot0: float, cells: Any, rest: Any, gain: float,
) -> None:  # pragma: no cover - compiled
    """The full pose (:meth:`handrig.pose.pipeline.PosePipeline.full_pose`): ``pose``
    becomes the 50 ``curves`` (the right hand's copied onto the left with ``mirror``)
    and a zero wrist, plus each hand's sag, ``idx_a`` at ``inc_a``/``rot_a`` then
    ``idx_b`` at ``inc_b``/``rot_b`` (``cells``: the grid's corner offsets, empty for
    no sag; ``abs_*``: on ``rest`` instead of on the curves)."""
    n_curves = curves.shape[0]
    for k in range(n_curves):
        pose[k] = curves[k]
    for k in range(n_curves, pose.shape[0]):
        pose[k] = 0.0
    if mirror:
        half = n_curves // 2
        for k in range(half):
            pose[half + k] = pose[k]
    if cells.shape[0] > 0:
        _sag_into(pose, idx_a, abs_a, inc_axis, rot_axis, rot0, cells, rest, gain, inc_a, rot_a)
        _sag_into(pose, idx_b, abs_b, inc_axis, rot_axis, rot0, cells, rest, gain, inc_b, rot_b)


@njit(cache=True, nogil=True)
def account_pose(
    pose: Any, pose_low: Any, pose_high: Any, clamped: Any, robot: bool, full_gain: Any,
    offset: Any, servo_index: Any, servo_low: Any, servo_high: Any, step: Any,
    clamps_by_servo: Any, raw_targets: Any, targets: Any, count_slewed: bool,
) -> tuple[int, int, int]:  # pragma: no cover - compiled
    """A full pose's counters after a write, and the pose clamped in place
    (:meth:`handrig.pose.pipeline.PosePipeline.account`): ``clamped`` gets
    ``pose`` clamped to ``pose_low``/``pose_high``; ``step`` the servos' values of the
    unclamped pose (``robot``: ``full_gain`` @ the clamped curves + ``offset``).
    Returns (pose values clamped, servo values outside ``servo_low``/``servo_high``,
    targets the slew limit held back when ``count_slewed``); ``clamps_by_servo`` adds
    the servo ones; ``pose`` ends clamped."""
    clamps = 0
    for k in range(pose.shape[0]):
        v = pose[k]
        c = v
        if v < pose_low[k]:
            c = pose_low[k]
        elif v > pose_high[k]:
            c = pose_high[k]
        clamped[k] = c
        if c != v:  # a NaN counts, as numpy's clip leaves it and NaN != NaN
            clamps += 1
    servo_clamps = 0
    for s in range(step.shape[0]):
        if robot:
            v = offset[s]
            for m in range(full_gain.shape[1]):
                v += full_gain[s, m] * clamped[m]
        else:
            v = pose[servo_index[s]]
        step[s] = v
        if v < servo_low[s] or v > servo_high[s]:
            servo_clamps += 1
            clamps_by_servo[s] += 1
    slewed = 0
    if count_slewed:
        for s in range(targets.shape[0]):
            if abs(raw_targets[s] - targets[s]) > 1e-9:
                slewed += 1
    for k in range(pose.shape[0]):
        pose[k] = clamped[k]
    return clamps, servo_clamps, slewed


def warm_up() -> None:
    """Compile (or load from the cache) every kernel with the types the loop uses."""
    f = np.zeros(2)
    servo_targets(f, f, np.zeros(4), np.zeros((4, 2)), f, np.array([0.0, 1.0]),
                  np.array([0.0, 1.0]), 0.0,
                  np.zeros((1, 1, 4, 2)), np.zeros(2, np.int64), 1.0, f - 2.0, f + 2.0, 0.5,
                  0.5, f - 1.0, f + 1.0, np.zeros(2), 1.0, False, np.zeros(2))
    expand_frame(f, np.zeros((2, 2)), f, f - 1.0, f + 1.0, f - 1.0, f + 1.0, np.zeros(2),
                 np.zeros(2, np.int64))
    hinge_features(f, f, np.zeros(4))
    robot_servo_targets(f, np.zeros(0), np.zeros(2), np.zeros((2, 2)), f, np.array([0.0, 1.0]),
                        np.array([0.0, 1.0]),
                        0.0, np.zeros((1, 1, 4, 2)), np.zeros(2, np.int64), 1.0, f - 2.0,
                        f + 2.0, 0.5, 0.5, f - 1.0, f + 1.0, np.zeros(2),
                        np.arange(3, dtype=np.int64),
                        np.arange(2, dtype=np.int64), f + 1.0, f, f - 1.0, f + 1.0,
                        np.zeros(2), 1.0, False, np.zeros(2))
    forearm_angles(np.array([0.0, 0.0, 0.0, 1.0]), False, 1.0, np.eye(3), 1.0, 1e-6, 0.5, 1.5)
    i2 = np.zeros(2, np.intp)
    pose_from_curves(f, False, np.zeros(3), i2, 0.5, 0.5, False, i2, 0.5, 0.5, True,
                     np.array([0.0, 1.0]), np.array([0.0, 1.0]), 0.0, np.zeros((1, 1, 4, 2)),
                     f, 1.0)
    account_pose(np.zeros(3), np.zeros(3) - 1.0, np.zeros(3) + 1.0, np.zeros(3), False,
                 np.zeros((2, 2)), f, i2, f - 1.0, f + 1.0, np.zeros(2),
                 np.zeros(2, np.int64), f, f, True)
    idx = np.zeros(2, np.intp)
    one_euro_step(f, 0.01, np.zeros(2), np.zeros(2), f + 1.0, f, f + 1.0)
    glove_controls(f, idx, f + 1.0, f, f - 1.0, f + 1.0, np.zeros(2), np.zeros(2), True,
                   False, 0.01, np.zeros(2), np.zeros(2), f + 1.0, f, f + 1.0, idx, np.zeros(2))
