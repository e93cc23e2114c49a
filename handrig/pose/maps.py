"""Linear maps from a glove's few control curves to all 50 curves, fitted on mocap.

Every map has the same readable form, per curve::

    curve = mean_deg + sum over controls c of gains[c] * (c - control_mean_deg[c])

so a person can open the TOML file and see which curve follows which control and how
much (degrees per degree). A control curve maps to itself (gain 1). Methods:

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
* ``robust`` (the default) — for each curve, the least-squares map of all controls under
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

Fitting refuses unrepaired glitches (``MocapCurves.require_clean``). A map records the
range each control covered in training (``control_range_deg``) so the runtime can count
how often the live controls leave it, and loading refuses implausible maps (a gain
beyond :data:`MAX_GAIN`, a curve the gains would swing far beyond its joint range over
the training range of the controls) and warns (:class:`MapWarning`) about doubtful ones.
"""

from __future__ import annotations

import itertools
import json
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.config.loading import build, check_joint_name, load_toml
from handrig.errors import ConfigError, DataError

FloatArray = NDArray[np.float64]
Method = Literal["robust", "paper", "ridge", "huber", "mean"]
METHODS: tuple[str, ...] = ("robust", "paper", "ridge", "huber", "mean")
DEFAULT_METHOD: Method = "robust"
"""Close to ridge on unseen gestures, never worse than the paper's map or the mean when
the controls are off (``handrig evaluate`` prints the comparison)."""
CONTROL_NOISE_DEG = 1.0
"""How far (deg, per control) the ``robust`` fit assumes live controls can sit from where
the training capture had them for the same hand shape."""
DEFAULT_GROUPS = 5
"""Contiguous blocks used as cross-validation groups when the clips are not given."""
MAX_GAIN = 100.0
"""A gain beyond this (deg per deg) is refused at load: no curve moves 100 times its control."""
SWING_WARN = 2.0
SWING_REFUSE = 10.0
"""Over the controls' training range (else their joint range), a curve whose map swings
more than these multiples of its joint range is warned about / refused at load."""
# Right-hand RMS, leave-one-clip-out on the reference: alpha 0.001 -> 3.45, 0.003 -> 3.44,
# 0.1 -> 4.02 deg.
RIDGE_ALPHA = 0.003
HUBER_DELTA = 1.345  # in units of the residual's robust std: 95 % efficiency for Gaussian noise
PAPER_RMSD_MAX = 1.0
FORMAT = "handrig-linear-map"
DEFAULT_RIGHT_CONTROLS: tuple[str, ...] = (
    "riThumbCMCx", "riThumbCMCy", "riThumbCMCz", "riIndexMCPy", "riPinkyMCPy",
)
"""The paper's advice (section 7): the thumb plus the MCP flexion of the index and pinky."""
DEFAULT_TWO_GLOVE_CONTROLS: tuple[str, ...] = DEFAULT_RIGHT_CONTROLS + tuple(
    hand.mirror_name(n) for n in DEFAULT_RIGHT_CONTROLS
)


@dataclass(frozen=True)
class LinearMap:
    """``curves = curve_means_deg + gains @ (controls - control_means_deg)``; vocabulary degrees.

    ``gains`` is (50, k), ``curve_means_deg`` (50,), ``control_means_deg`` (k,).
    """

    controls: tuple[str, ...]
    control_means_deg: FloatArray
    curve_means_deg: FloatArray
    gains: FloatArray
    method: str
    trained_on: tuple[str, ...] = ()
    profile: str = ""
    frames: int = 0
    fps: float = 0.0
    description: str = ""
    fit_rms_deg: FloatArray | None = field(default=None, compare=False)
    control_range_deg: FloatArray | None = field(default=None, compare=False)
    """(k, 2) lowest and highest value of each control in the training data."""
    fitting: str = ""
    """How it was fit (method settings, cross-validation groups)."""
    evaluation: tuple[str, ...] = ()
    """Held-out figures measured when it was fit (``handrig fit-map --evaluate``)."""

    def __post_init__(self) -> None:
        k = len(self.controls)
        if self.gains.shape != (len(hand.CURVE_NAMES), k):
            raise DataError(f"gains must be (50, {k}), got {self.gains.shape}")
        if self.control_means_deg.shape != (k,) or self.curve_means_deg.shape != (50,):
            raise DataError("control_means_deg must be (k,) and curve_means_deg (50,)")
        if self.control_range_deg is not None and self.control_range_deg.shape != (k, 2):
            raise DataError(f"control_range_deg must be ({k}, 2), got"
                            f" {self.control_range_deg.shape}")
        for name, arr in (("gains", self.gains), ("curve_means_deg", self.curve_means_deg),
                          ("control_means_deg", self.control_means_deg)):
            if not np.isfinite(arr).all():
                raise DataError(f"map {name} contain NaN or inf")

    @property
    def control_indices(self) -> NDArray[np.intp]:
        return np.array([hand.curve_index(c) for c in self.controls], dtype=np.intp)

    def predict(self, controls_deg: FloatArray) -> FloatArray:
        """(n, k) control values -> (n, 50) curves, unclamped (see :class:`Expander`)."""
        x = np.asarray(controls_deg, dtype=np.float64)
        out: FloatArray = self.curve_means_deg + (x - self.control_means_deg) @ self.gains.T
        return out

    def to_toml(self) -> str:
        """The map as a commented, human-readable TOML document."""
        q = json.dumps
        lines = [
            "# handrig linear map (vocabulary convention: degrees, flexion positive).",
            "# For every curve:",
            "#   curve = mean_deg + sum over controls c of gains[c] * (c - control_means_deg[c])",
            "# gains are degrees of the curve per degree of the control; a curve without",
            "# gains is held at its mean. Written by `handrig fit-map`.",
            f"format = {q(FORMAT)}",
            "version = 1",
            f"method = {q(self.method)}",
            'convention = "vocabulary"',
            f"description = {q(self.description)}",
            f"profile = {q(self.profile)}",
            f"trained_on = [{', '.join(q(t) for t in self.trained_on)}]",
            f"frames = {int(self.frames)}",
            f"fps = {_num(self.fps)}",
            f"controls = [{', '.join(q(c) for c in self.controls)}]",
            f"control_means_deg = [{', '.join(_num(v) for v in self.control_means_deg)}]",
        ]
        if self.control_range_deg is not None:
            rng = ", ".join(f"[{_num(lo)}, {_num(hi)}]" for lo, hi in self.control_range_deg)
            lines.append("# lowest and highest value of each control in the training data")
            lines.append(f"control_range_deg = [{rng}]")
        if self.fitting:
            lines.append(f"fitting = {q(self.fitting)}")
        if self.evaluation:
            lines.append("# held-out RMS error (deg) measured when the map was fit")
            lines.append("evaluation = [")
            lines += [f"  {q(e)}," for e in self.evaluation]
            lines.append("]")
        lines.append("")
        for i, name in enumerate(hand.CURVE_NAMES):
            g = ", ".join(
                f"{c} = {_num(self.gains[i, j], 5)}"
                for j, c in enumerate(self.controls) if abs(self.gains[i, j]) >= 5e-6
            )
            lines.append(f"[curves.{name}]")
            lines.append(f"mean_deg = {_num(self.curve_means_deg[i])}")
            lines.append(f"gains = {{ {g} }}" if g else "gains = {}")
            if self.fit_rms_deg is not None:
                lines.append(f"fit_rms_deg = {_num(self.fit_rms_deg[i], 3)}")
            lines.append("")
        return "\n".join(lines)

    def save(self, path: str | Path) -> Path:
        """Write :meth:`to_toml` to ``path``."""
        p = Path(path)
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_text(self.to_toml())
        except OSError as exc:
            raise DataError(f"cannot write map {p}: {exc}") from None
        return p

    @classmethod
    def load(cls, path: str | Path) -> LinearMap:
        """Read and validate a map file; ConfigError names the file and the key."""
        data = load_toml(path)
        try:
            mf = build(_MapFile, data)
        except ConfigError as exc:
            raise exc.located(str(path)) from None
        except (TypeError, ValueError) as exc:  # a shape the builder cannot take
            raise ConfigError(f"malformed map: {exc}", file=str(path)) from None
        k = len(mf.controls)
        gains = np.zeros((50, k))
        means = np.zeros(50)
        fit = np.full(50, np.nan)
        for i, name in enumerate(hand.CURVE_NAMES):
            entry = mf.curves[name]
            means[i] = entry.mean_deg
            for c, g in entry.gains.items():
                gains[i, mf.controls.index(c)] = g
            if entry.fit_rms_deg is not None:
                fit[i] = entry.fit_rms_deg
        rng = None if mf.control_range_deg is None else np.array(mf.control_range_deg,
                                                                  dtype=np.float64)
        try:
            lm = cls(
                controls=mf.controls, control_means_deg=np.array(mf.control_means_deg),
                curve_means_deg=means, gains=gains, method=mf.method, trained_on=mf.trained_on,
                profile=mf.profile, frames=mf.frames, fps=mf.fps, description=mf.description,
                fit_rms_deg=None if np.isnan(fit).any() else fit, control_range_deg=rng,
                fitting=mf.fitting, evaluation=mf.evaluation,
            )
        except DataError as exc:
            raise ConfigError(str(exc), file=str(path)) from None
        for msg in lm.check_plausible(str(path)):
            warnings.warn(msg, MapWarning, stacklevel=2)
        return lm

    def swing_deg(self) -> FloatArray | None:
        """How far (deg) each curve moves as the controls sweep their training range
        (``sum |gain| * range``); None without a recorded range."""
        if self.control_range_deg is None:
            return None
        out: FloatArray = np.abs(self.gains) @ (self.control_range_deg[:, 1]
                                                - self.control_range_deg[:, 0])
        return out

    def check_plausible(self, source: str = "<map>") -> list[str]:
        """Raise ConfigError (naming ``source`` and the key) for an implausible map;
        return warnings for doubtful values (``load`` issues them as :class:`MapWarning`)."""
        idx = set(int(i) for i in self.control_indices)
        for i, name in enumerate(hand.CURVE_NAMES):
            j = int(np.argmax(np.abs(self.gains[i])))
            g = float(self.gains[i, j])
            if i not in idx and abs(g) > MAX_GAIN:
                raise ConfigError(
                    "gain is implausible: no curve moves that many degrees per degree of a"
                    " control (refit the map with handrig fit-map)",
                    file=source, key=f"curves.{name}.gains.{self.controls[j]}", value=g,
                    allowed=f"|gain| <= {MAX_GAIN:g}",
                )
        if self.control_range_deg is not None:
            for j, c in enumerate(self.controls):
                lo, hi = self.control_range_deg[j]
                if not lo <= self.control_means_deg[j] <= hi:
                    raise ConfigError(
                        f"the mean of {c} ({self.control_means_deg[j]:.4g}) lies outside its"
                        f" training range [{lo:.4g}, {hi:.4g}]", file=source,
                        key=f"control_range_deg[{j}]", allowed="low <= mean <= high",
                    )
        lim = hand.curve_limits_deg()
        span = lim[:, 1] - lim[:, 0]
        means = self.curve_means_deg.copy()
        means[self.control_indices] = self.control_means_deg
        far = np.maximum(lim[:, 0] - means, means - lim[:, 1]) / span
        if far.max() > 1.0:
            i = int(np.argmax(far))
            name = hand.CURVE_NAMES[i]
            key = (f"control_means_deg[{self.controls.index(name)}]" if name in self.controls
                   else f"curves.{name}.mean_deg")
            raise ConfigError(
                f"the mean of {name} lies more than its joint range beyond its joint limits"
                f" [{lim[i, 0]:g}, {lim[i, 1]:g}] deg: not a pose of this hand (wrong"
                " convention or a corrupt file)", file=source, key=key, value=float(means[i]),
            )
        swing = self.swing_deg()
        if swing is None:
            return []
        ratio = swing / (lim[:, 1] - lim[:, 0])
        doubtful = [i for i in np.argsort(-ratio) if i not in idx and ratio[i] > SWING_WARN]
        if not doubtful:
            return []
        i = int(doubtful[0])
        name = hand.CURVE_NAMES[i]
        j = int(np.argmax(np.abs(self.gains[i])))
        detail = (f"over the controls' training range the gains swing {name} by"
                  f" {swing[i]:.0f} deg, {ratio[i]:.1f} times its joint range (largest gain"
                  f" {self.gains[i, j]:.4g} on {self.controls[j]})")
        if ratio[i] > SWING_REFUSE:
            raise ConfigError(
                f"{detail}: gains far beyond what the training data supports; refit the map",
                file=source, key=f"curves.{name}.gains",
                allowed=f"a swing of at most {SWING_REFUSE:g} joint ranges",
            )
        more = f" ({len(doubtful) - 1} more curve(s) above {SWING_WARN:g})" if len(
            doubtful) > 1 else ""
        return [f"{source}: key 'curves.{name}.gains': {detail}{more}; such outputs often"
                " sit at the joint limits"]


class MapWarning(UserWarning):
    """A map loaded, but some of its values look doubtful (the message says which)."""


def _num(v: float, decimals: int = 4) -> str:
    if not math.isfinite(float(v)):
        raise DataError(f"map value {v} is not finite")
    return repr(round(float(v), decimals) + 0.0)


@dataclass(frozen=True)
class _CurveEntry:
    mean_deg: float
    gains: dict[str, float] = field(default_factory=dict)
    fit_rms_deg: float | None = None


@dataclass(frozen=True)
class _MapFile:
    format: Literal["handrig-linear-map"]
    version: Literal[1]
    method: str
    convention: Literal["vocabulary"]
    controls: tuple[str, ...]
    control_means_deg: tuple[float, ...]
    curves: dict[str, _CurveEntry]
    description: str = ""
    profile: str = ""
    trained_on: tuple[str, ...] = ()
    frames: int = 0
    fps: float = 0.0
    control_range_deg: tuple[tuple[float, float], ...] | None = None
    fitting: str = ""
    evaluation: tuple[str, ...] = ()

    def check(self) -> None:
        if not self.controls:
            raise ConfigError("a map needs at least one control", key="controls")
        for i, c in enumerate(self.controls):
            check_joint_name(c, f"controls[{i}]")
            if c not in hand.CURVE_NAMES:
                raise ConfigError("a control must be one of the 50 curves", key=f"controls[{i}]",
                                  value=c)
        if len(set(self.controls)) != len(self.controls):
            raise ConfigError("controls repeat a name", key="controls", value=list(self.controls))
        if len(self.control_means_deg) != len(self.controls):
            raise ConfigError(
                f"needs one mean per control ({len(self.controls)})", key="control_means_deg",
                value=list(self.control_means_deg),
            )
        for name, entry in self.curves.items():
            if name not in hand.CURVE_NAMES:
                check_joint_name(name, f"curves.{name}")
                raise ConfigError("not one of the 50 curves", key=f"curves.{name}")
            for c in entry.gains:
                if c not in self.controls:
                    raise ConfigError(
                        "gain on a name that is not a control", key=f"curves.{name}.gains.{c}",
                        allowed=", ".join(self.controls),
                    )
        if self.control_range_deg is not None:
            if len(self.control_range_deg) != len(self.controls):
                raise ConfigError(
                    f"needs one [low, high] per control ({len(self.controls)})",
                    key="control_range_deg", value=[list(r) for r in self.control_range_deg],
                )
            for j, (lo, hi) in enumerate(self.control_range_deg):
                if lo > hi:
                    raise ConfigError("inverted range: low must not exceed high",
                                      key=f"control_range_deg[{j}]", value=[lo, hi])
        missing = [n for n in hand.CURVE_NAMES if n not in self.curves]
        if missing:
            raise ConfigError(
                f"{len(missing)} curve(s) missing, first {missing[0]}", key="curves",
                allowed="a [curves.NAME] table for each of the 50 curves",
            )


_FITTING = {
    "ridge": "ridge: least squares on all controls, penalty alpha = {alpha:g} on standardised"
             " controls",
    "huber": "huber: Huber loss (delta {delta:g} robust std), penalty alpha = {alpha:g}",
    "paper": "paper: each curve follows its best single control (Jörg & O'Sullivan 4.2)",
    "mean": "mean: every curve that is not a control holds its training mean",
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
    from handrig.offline.analysis import rmsd_matrices

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
    if method == "robust":
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
        fitting=fitting or _FITTING.get(method, "").format(alpha=alpha, delta=huber_delta),
        evaluation=tuple(str(e) for e in meta.get("evaluation", ()) or ()),  # type: ignore[attr-defined]
    )
    fit = np.sqrt(np.mean((lm.predict(x) - y) ** 2, axis=0))
    return LinearMap(**{**lm.__dict__, "fit_rms_deg": fit})
