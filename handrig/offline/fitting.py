"""Fitting :class:`~handrig.pose.maps.LinearMap` maps on mocap curves.

Methods:
* ``paper`` — Jörg & O'Sullivan 4.2: each curve follows the one control with the lowest
  rmsd (rmsd1 or rmsd2) by the mean/std-preserving map, gain ``+-std(a)/std(b)``. A curve
  with a range below 1 deg, or whose best rmsd is not below ``paper_rmsd_max`` (1.0:
  beyond it following a control is worse than the mean, ``rmsd^2 = 2 - 2|r|``), is its mean.
* ``ridge`` — least squares on all controls at once (the paper's future work: "more
  complex models ... relationships with more than one joint rotation"), with a ridge
  penalty ``alpha`` on standardised controls that keeps gains small when controls are
  collinear (the capture copies MCP flexion to PIP and DIP).
* ``huber`` — the same multi-control fit with the Huber loss (iteratively reweighted
  least squares, robust scale from the median absolute deviation), so a few glitched or
  atypical frames do not pull the gains.
* ``piecewise`` (the default) — a piecewise-linear map: each control ``c`` also enters as
  its hinge ``max(0, c - knot)`` at its training median (the slope on a control may change
  once, halfway through its training data), every gain fit at once under the same
  control-noise assumption as ``robust`` (controls off by ``piecewise_noise_deg``; a
  control off by ``e`` moves its hinge by at most ``e``, so the penalty
  ``noise^2 * |g|^2`` covers both halves), shrunk toward zero, that is toward the mean
  pose. Chosen by the blocked validation (:mod:`handrig.offline.validation`).
* ``robust`` — for each curve, the least-squares map of all controls under
  the assumption that every control is off by about ``control_noise_deg`` (1 deg) from
  what the training capture showed (a calibration offset, a rest pose the capture did
  not hold): the expected error ``E[(y - g.(x + e))^2]`` with independent offsets ``e``
  of that size is the least-squares error plus ``noise^2 * |g|^2`` (Tikhonov
  regularisation in degrees: C. Bishop, "Training with noise is equivalent to Tikhonov
  regularization", Neural Computation 7, 1995). The
  penalty is taken toward the ``paper`` gains rather than toward zero, so a curve that
  copies one control keeps the copy. A gain on a control that moved little in training
  (the left hand of a gesturing performer) then costs what it would cost when that
  control sits a degree elsewhere, which keeps several controls from combining into a
  large extrapolation. Then, per curve, leave-one-group-out cross-validation over the
  training clips picks between that map and the constant mean: no curve follows the
  controls unless doing so beat the mean on clips it was not fitted on.
* ``mean`` — every non-control curve is its mean (the baseline).

Every method records each non-control curve's training range, inside its anatomical
range, in the map (``curve_range_deg``): the runtime clips the curve's output to it (a
clipped-linear map), so controls beyond what the capture showed do not extrapolate the
hand past any shape in it, nor past its joints. Fitting refuses unrepaired glitches
(``MocapCurves.require_clean``).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.errors import DataError
from handrig.offline.analysis import rmsd_matrices
from handrig.pose.maps import LinearMap

FloatArray = NDArray[np.float64]
Method = Literal["piecewise", "robust", "paper", "ridge", "huber", "mean"]
METHODS: tuple[str, ...] = ("piecewise", "robust", "paper", "ridge", "huber", "mean")
DEFAULT_METHOD: Method = "piecewise"
"""In the blocked validation the lowest right-hand error of the methods on calm frames,
with the controls off and on the other hand, and tied with ridge on all frames
(``handrig evaluate`` prints the comparison; docs/measurements.md, issue 42)."""
PIECEWISE_NOISE_DEG = 1.5
"""How far (deg, per control) the ``piecewise`` fit assumes live controls can sit from
where the training capture had them. Chosen on the blocked validation among 1.0, 1.5 and
2.0 (docs/measurements.md, issue 42)."""
CONTROL_NOISE_DEG = 0.8
"""How far (deg, per control) the ``robust`` fit assumes live controls can sit from where
the training capture had them for the same hand shape. With the clipped output range
(below) 0.8 keeps the ``offset`` split of ``handrig evaluate`` (controls off by 2 deg)
no worse than 1.0 did without it, and is closer on unseen clips (docs/measurements.md)."""
DEFAULT_GROUPS = 5
"""Contiguous blocks used as cross-validation groups when the clips are not given."""
# Right-hand RMS, leave-one-clip-out on the reference: alpha 0.001 -> 3.45, 0.003 -> 3.44,
# 0.1 -> 4.02 deg.
RIDGE_ALPHA = 0.003
HUBER_DELTA = 1.345  # in units of the residual's robust std: 95 % efficiency for Gaussian noise
PAPER_RMSD_MAX = 1.0


_FITTING = {
    "ridge": "ridge: least squares on all controls, penalty alpha = {alpha:g} on standardised"
             " controls",
    "huber": "huber: Huber loss (delta {delta:g} robust std), penalty alpha = {alpha:g}",
    "paper": "paper: each curve follows its best single control (Jörg & O'Sullivan 4.2)",
    "mean": "mean: every curve that is not a control holds its training mean",
    "piecewise": "piecewise: linear in each control and its hinge at its training median,"
                 " gains shrunk toward the mean pose for controls off by {noise:g} deg",
}


def _design(x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    mean = x.mean(axis=0)
    scale = x.std(axis=0)
    scale = np.where(scale > 1e-9, scale, 1.0)
    return (x - mean) / scale, mean, scale


def _fit_ridge(x: FloatArray, y: FloatArray, alpha: float) -> tuple[FloatArray, FloatArray]:
    """Gains (m, k) and curve means (m,) by ridge on standardised controls (penalty n*alpha)."""
    z, _, scale = _design(x)
    yc = y - y.mean(axis=0)
    n, k = z.shape
    a = z.T @ z + n * alpha * np.eye(k)
    w = np.linalg.solve(a, z.T @ yc)  # (k, m)
    return (w / scale[:, None]).T, y.mean(axis=0)


def _fit_huber(
    x: FloatArray, y: FloatArray, alpha: float, delta: float, iterations: int = 30
) -> tuple[FloatArray, FloatArray]:
    """Huber-loss multi-control fit per curve by IRLS (intercept fitted too)."""
    z, _, scale = _design(x)
    n, k = z.shape
    za = np.hstack([z, np.ones((n, 1))])
    pen = n * alpha * np.eye(k + 1)
    pen[k, k] = 0.0
    m = y.shape[1]
    gains = np.zeros((m, k))
    means = np.zeros(m)
    for j in range(m):
        yj = y[:, j]
        w = np.ones(n)
        beta = np.zeros(k + 1)
        for _ in range(iterations):
            zw = za * w[:, None]
            beta_new = np.linalg.solve(za.T @ zw + pen, zw.T @ yj)
            r = yj - za @ beta_new
            s = 1.4826 * np.median(np.abs(r - np.median(r)))
            s = max(s, 1e-6)  # an exact fit of most frames: weights tend to least absolute values
            u = np.abs(r) / (delta * s)
            w = np.where(u <= 1.0, 1.0, 1.0 / np.maximum(u, 1e-12))
            done = np.max(np.abs(beta_new - beta)) < 1e-6
            beta = beta_new
            if done:
                break
        gains[j] = beta[:k] / scale
        means[j] = beta[k]  # value at the controls' means (z = 0)
    return gains, means


def _fit_paper(
    x: FloatArray, y: FloatArray, rmsd_max: float, range_min_deg: float
) -> tuple[FloatArray, FloatArray]:
    """Section 4.2: each curve follows its best single control, mean/std preserved."""
    k = x.shape[1]
    both = np.hstack([x, y])
    r1, r2 = rmsd_matrices(both)
    sx, sy = x.std(axis=0), y.std(axis=0)
    m = y.shape[1]
    gains = np.zeros((m, k))
    ranges = np.ptp(y, axis=0)
    for j in range(m):
        if ranges[j] < range_min_deg:
            continue
        d1, d2 = r1[k + j, :k], r2[k + j, :k]
        best = np.minimum(d1, d2)
        c = int(np.argmin(best))
        if best[c] >= rmsd_max or sx[c] <= 0:
            continue
        sign = 1.0 if d1[c] <= d2[c] else -1.0
        gains[j, c] = sign * sy[j] / sx[c]
    return gains, y.mean(axis=0)


def _shrunk(x: FloatArray, y: FloatArray, noise_deg: float, prior: FloatArray) -> FloatArray:
    """Gains (m, k) minimising ``mean((y - g.x)^2) + noise^2 |g - prior|^2`` (centred data)."""
    xc = x - x.mean(axis=0)
    yc = y - y.mean(axis=0)
    n, k = x.shape
    a = xc.T @ xc / n + noise_deg ** 2 * np.eye(k)
    b = xc.T @ yc / n + noise_deg ** 2 * prior.T
    g: FloatArray = np.linalg.solve(a, b).T
    return g


def _fit_robust(
    x: FloatArray, y: FloatArray, groups: NDArray[np.intp], noise_deg: float,
    paper_rmsd_max: float, range_min_deg: float,
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """The ``robust`` method: shrunk multi-control gains, or the mean where held-out
    groups say the mean does better. Returns gains, means and which curves follow."""
    prior, means = _fit_paper(x, y, paper_rmsd_max, range_min_deg)
    gains = _shrunk(x, y, noise_deg, prior)
    err_fit = np.zeros(y.shape[1])
    err_mean = np.zeros(y.shape[1])
    for g in np.unique(groups):
        tr, te = groups != g, groups == g
        xt, yt = x[tr], y[tr]
        p_tr, _ = _fit_paper(xt, yt, paper_rmsd_max, range_min_deg)
        gt = _shrunk(xt, yt, noise_deg, p_tr)
        pred = yt.mean(axis=0) + (x[te] - xt.mean(axis=0)) @ gt.T
        err_fit += ((pred - y[te]) ** 2).sum(axis=0)
        err_mean += ((yt.mean(axis=0) - y[te]) ** 2).sum(axis=0)
    follows = err_fit < err_mean
    gains[~follows] = 0.0
    return gains, means, follows


def _fit_piecewise(x: FloatArray, y: FloatArray, noise_deg: float
                   ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The ``piecewise`` method: gains (m, k), hinge gains (m, k), knots (k,) and the curves'
    values at the controls' means (m,), minimising ``mean((y - G.(f - mean f))^2) +
    noise^2 |G|^2`` over the features ``f = (x, max(0, x - knots))``."""
    k = x.shape[1]
    knots = np.median(x, axis=0)
    f = np.hstack([x, np.maximum(x - knots, 0.0)])
    fc = f - f.mean(axis=0)
    yc = y - y.mean(axis=0)
    n = f.shape[0]
    a = fc.T @ fc / n + noise_deg ** 2 * np.eye(2 * k)
    g = np.linalg.solve(a, fc.T @ yc / n).T  # (m, 2k)
    at_means = np.maximum(x.mean(axis=0) - knots, 0.0) - f[:, k:].mean(axis=0)
    return g[:, :k], g[:, k:], knots, y.mean(axis=0) + g[:, k:] @ at_means


def block_groups(n_frames: int, count: int = DEFAULT_GROUPS) -> NDArray[np.intp]:
    """Frame labels 0 .. count - 1 for ``count`` contiguous blocks (cross-validation groups)."""
    edges = np.linspace(0, n_frames, count + 1).round().astype(np.intp)
    labels = np.zeros(n_frames, dtype=np.intp)
    for i, (a, b) in enumerate(itertools.pairwise(edges)):
        labels[a:b] = i
    return labels


def fit_map(
    curves: FloatArray,
    controls: Sequence[str],
    method: str = DEFAULT_METHOD,
    *,
    alpha: float = RIDGE_ALPHA,
    huber_delta: float = HUBER_DELTA,
    paper_rmsd_max: float = PAPER_RMSD_MAX,
    range_min_deg: float = 1.0,
    control_noise_deg: float = CONTROL_NOISE_DEG,
    piecewise_noise_deg: float = PIECEWISE_NOISE_DEG,
    groups: Sequence[int] | NDArray[np.intp] | None = None,
    groups_name: str = "",
    **meta: object,
) -> LinearMap:
    """Fit a map from ``controls`` to all 50 curves on ``curves`` (frames x 50, vocabulary).

    ``groups``: one label per frame (e.g. the gesture clip), the units the ``robust``
    method holds out in its per-curve cross-validation (None: :data:`DEFAULT_GROUPS`
    contiguous blocks); ``groups_name`` says what they are in the map's ``fitting`` note
    (default "clips", or "contiguous blocks" without groups). ``meta`` goes to the map's
    descriptive fields (trained_on, profile, fps, description, evaluation).
    """
    if method not in METHODS:
        raise DataError(f"unknown method {method!r}; methods: {', '.join(METHODS)}")
    ctrl = tuple(controls)
    if not ctrl:
        raise DataError("a map needs at least one control curve")
    for c in ctrl:
        hand.curve(c)
    if len(set(ctrl)) != len(ctrl):
        raise DataError(f"controls repeat a name: {', '.join(ctrl)}")
    y = np.asarray(curves, dtype=np.float64)
    if y.ndim != 2 or y.shape[1] != 50 or y.shape[0] < len(ctrl) + 2:
        raise DataError(f"fitting needs frames x 50 curves with more frames than controls,"
                        f" got {y.shape}")
    if not np.isfinite(y).all():
        raise DataError("curves contain NaN/inf: repair them first (--despike)")
    idx = np.array([hand.curve_index(c) for c in ctrl], dtype=np.intp)
    x = y[:, idx]
    fitting = ""
    knots: FloatArray | None = None
    hinge: FloatArray | None = None
    if method == "piecewise":
        if not piecewise_noise_deg > 0:
            raise DataError(f"control noise must be positive, got {piecewise_noise_deg}")
        gains, hinge, knots, means = _fit_piecewise(x, y, piecewise_noise_deg)
        hinge[idx] = 0.0  # a control passes through unchanged
    elif method == "robust":
        labels = (block_groups(y.shape[0]) if groups is None
                  else np.asarray(groups, dtype=np.intp))
        if labels.shape != (y.shape[0],):
            raise DataError(f"groups needs one label per frame ({y.shape[0]}), got"
                            f" {labels.shape}")
        n_groups = len(np.unique(labels))
        default_name = "clips" if groups is not None else "contiguous blocks"
        if n_groups < 2:
            raise DataError("the robust method needs at least 2 groups (clips) to hold out")
        if not control_noise_deg > 0:
            raise DataError(f"control noise must be positive, got {control_noise_deg}")
        gains, means, follows = _fit_robust(x, y, labels, control_noise_deg, paper_rmsd_max,
                                            range_min_deg)
        held = [n for n, f in zip(hand.CURVE_NAMES, follows, strict=True)
                if not f and n not in ctrl]
        fitting = (f"robust: gains shrunk toward the paper map for controls off by"
                   f" {control_noise_deg:g} deg; per curve, follow the controls or hold the mean"
                   f" by leave-one-group-out over {n_groups} groups"
                   f" ({groups_name or default_name});"
                   f" {len(held)} curve(s) held at the mean")
    elif method == "ridge":
        gains, means = _fit_ridge(x, y, alpha)
    elif method == "huber":
        gains, means = _fit_huber(x, y, alpha, huber_delta)
    elif method == "paper":
        gains, means = _fit_paper(x, y, paper_rmsd_max, range_min_deg)
    else:
        gains, means = np.zeros((50, len(ctrl))), y.mean(axis=0)
    x_mean = x.mean(axis=0)
    lim = hand.curve_limits_deg()  # the training range inside the anatomical one
    curve_range = np.clip(np.stack([y.min(axis=0), y.max(axis=0)], axis=1),
                          lim[:, :1], lim[:, 1:])
    curve_range[idx] = (-np.inf, np.inf)  # a control passes through, never clipped
    means = means.copy()
    gains[idx] = np.eye(len(ctrl))  # a control passes through unchanged
    means[idx] = x_mean
    lm = LinearMap(
        controls=ctrl, control_means_deg=x_mean, curve_means_deg=means, gains=gains,
        method=method,
        trained_on=tuple(str(t) for t in meta.get("trained_on", ()) or ()),  # type: ignore[attr-defined]
        profile=str(meta.get("profile", "")), frames=int(y.shape[0]),
        fps=float(meta.get("fps", 0.0) or 0.0),  # type: ignore[arg-type]
        description=str(meta.get("description", "")),
        control_range_deg=np.stack([x.min(axis=0), x.max(axis=0)], axis=1),
        curve_range_deg=curve_range,
        fitting=(fitting or _FITTING.get(method, "").format(alpha=alpha, delta=huber_delta,
                                                            noise=piecewise_noise_deg))
        + (f"; {meta['conditioning']}" if meta.get("conditioning") else ""),
        evaluation=tuple(str(e) for e in meta.get("evaluation", ()) or ()),  # type: ignore[attr-defined]
        knots_deg=knots, hinge_gains=hinge,
    )
    fit = np.sqrt(np.mean((lm.predict(x) - y) ** 2, axis=0))
    return LinearMap(**{**lm.__dict__, "fit_rms_deg": fit})
