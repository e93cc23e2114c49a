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
* ``mean`` — every non-control curve is its mean (the baseline).

Fitting refuses unrepaired glitches (``MocapCurves.require_clean``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.config import build, check_joint_name, load_toml
from handrig.errors import ConfigError, DataError

FloatArray = NDArray[np.float64]
Method = Literal["paper", "ridge", "huber", "mean"]
METHODS: tuple[str, ...] = ("paper", "ridge", "huber", "mean")
DEFAULT_METHOD: Method = "ridge"
"""Best on unseen gestures (leave-one-clip-out on the reference capture; see evaluate)."""
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

    def __post_init__(self) -> None:
        k = len(self.controls)
        if self.gains.shape != (len(hand.CURVE_NAMES), k):
            raise DataError(f"gains must be (50, {k}), got {self.gains.shape}")
        if self.control_means_deg.shape != (k,) or self.curve_means_deg.shape != (50,):
            raise DataError("control_means_deg must be (k,) and curve_means_deg (50,)")

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
            "",
        ]
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
        return cls(
            controls=mf.controls, control_means_deg=np.array(mf.control_means_deg),
            curve_means_deg=means, gains=gains, method=mf.method, trained_on=mf.trained_on,
            profile=mf.profile, frames=mf.frames, fps=mf.fps, description=mf.description,
            fit_rms_deg=None if np.isnan(fit).any() else fit,
        )


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
        missing = [n for n in hand.CURVE_NAMES if n not in self.curves]
        if missing:
            raise ConfigError(
                f"{len(missing)} curve(s) missing, first {missing[0]}", key="curves",
                allowed="a [curves.NAME] table for each of the 50 curves",
            )


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
    from handrig.analysis import rmsd_matrices

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


def fit_map(
    curves: FloatArray,
    controls: Sequence[str],
    method: str = DEFAULT_METHOD,
    *,
    alpha: float = RIDGE_ALPHA,
    huber_delta: float = HUBER_DELTA,
    paper_rmsd_max: float = PAPER_RMSD_MAX,
    range_min_deg: float = 1.0,
    **meta: object,
) -> LinearMap:
    """Fit a map from ``controls`` to all 50 curves on ``curves`` (frames x 50, vocabulary).

    ``meta`` goes to the map's descriptive fields (trained_on, profile, frames, fps,
    description).
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
    if method == "ridge":
        gains, means = _fit_ridge(x, y, alpha)
    elif method == "huber":
        gains, means = _fit_huber(x, y, alpha, huber_delta)
    elif method == "paper":
        gains, means = _fit_paper(x, y, paper_rmsd_max, range_min_deg)
    else:
        gains, means = np.zeros((50, len(ctrl))), y.mean(axis=0)
    x_mean = x.mean(axis=0)
    gains[idx] = np.eye(len(ctrl))  # a control passes through unchanged
    means[idx] = x_mean
    lm = LinearMap(
        controls=ctrl, control_means_deg=x_mean, curve_means_deg=means, gains=gains,
        method=method,
        trained_on=tuple(str(t) for t in meta.get("trained_on", ()) or ()),  # type: ignore[attr-defined]
        profile=str(meta.get("profile", "")), frames=int(y.shape[0]),
        fps=float(meta.get("fps", 0.0) or 0.0),  # type: ignore[arg-type]
        description=str(meta.get("description", "")),
    )
    fit = np.sqrt(np.mean((lm.predict(x) - y) ** 2, axis=0))
    return LinearMap(**{**lm.__dict__, "fit_rms_deg": fit})
