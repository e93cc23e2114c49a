"""Linear maps from a glove's few control curves to all 50 curves, and their files.

Every map has the same readable form, per curve::

    curve = mean_deg + sum over controls c of gains[c] * (c - control_mean_deg[c])

so a person can open the TOML file and see which curve follows which control and how
much (degrees per degree). A control curve maps to itself (gain 1). A piecewise-linear
map also records one knot per control (``knots_deg``) and per curve ``hinge_gains``: above
its knot a control's slope changes by its hinge gain, so each curve gets the term
``hinge_gains[c] * (max(0, c - knot[c]) - max(0, control_mean_deg[c] - knot[c]))``
(zero at the controls' means, so ``mean_deg`` stays the curve at the controls' means).
A curve may also carry ``range_deg = [low, high]``, the range it covered in training:
the map's output for that curve is clipped to it (a clipped-linear map: the hand never
takes a shape beyond what the capture showed, however far the controls extrapolate),
before passive sag and the joint limits. The maps are fit offline from mocap
(:mod:`handrig.offline.fitting`, where the methods are described).

A map records the range each control covered in training (``control_range_deg``) so the
runtime can count how often the live controls leave it, and loading refuses implausible
maps (a gain beyond :data:`MAX_GAIN`, a curve the gains would swing far beyond its joint
range over the training range of the controls) and warns (:class:`MapWarning`) about
doubtful ones.
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.config.loading import build, check_joint_name, load_toml
from handrig.errors import ConfigError, DataError

FloatArray = NDArray[np.float64]
MAX_GAIN = 100.0
"""A gain beyond this (deg per deg) is refused at load: no curve moves 100 times its control."""
SWING_WARN = 2.0
SWING_REFUSE = 10.0
"""Over the controls' training range (else their joint range), a curve whose map swings
more than these multiples of its joint range is warned about / refused at load."""
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
    curve_range_deg: FloatArray | None = field(default=None, compare=False)
    """(50, 2) the range each curve's output is clipped to (-inf/inf: not clipped)."""
    fitting: str = ""
    """How it was fit (method settings, cross-validation groups)."""
    evaluation: tuple[str, ...] = ()
    """Held-out figures measured when it was fit (``handrig fit-map --evaluate``)."""
    knots_deg: FloatArray | None = field(default=None, compare=False)
    """(k,) a piecewise-linear map's knot per control (None: a linear map)."""
    hinge_gains: FloatArray | None = field(default=None, compare=False)
    """(50, k) the change of each curve's slope above each control's knot."""

    def __post_init__(self) -> None:
        k = len(self.controls)
        if self.gains.shape != (len(hand.CURVE_NAMES), k):
            raise DataError(f"gains must be (50, {k}), got {self.gains.shape}")
        if (self.knots_deg is None) != (self.hinge_gains is None):
            raise DataError("a piecewise-linear map needs both knots_deg and hinge_gains")
        if self.knots_deg is not None and self.hinge_gains is not None:
            if self.knots_deg.shape != (k,) or self.hinge_gains.shape != (50, k):
                raise DataError(f"knots_deg must be ({k},) and hinge_gains (50, {k}), got"
                                f" {self.knots_deg.shape} and {self.hinge_gains.shape}")
            if not (np.isfinite(self.knots_deg).all() and np.isfinite(self.hinge_gains).all()):
                raise DataError("map knots_deg or hinge_gains contain NaN or inf")
        if self.control_means_deg.shape != (k,) or self.curve_means_deg.shape != (50,):
            raise DataError("control_means_deg must be (k,) and curve_means_deg (50,)")
        if self.control_range_deg is not None and self.control_range_deg.shape != (k, 2):
            raise DataError(f"control_range_deg must be ({k}, 2), got"
                            f" {self.control_range_deg.shape}")
        if self.curve_range_deg is not None:
            r = self.curve_range_deg
            if r.shape != (50, 2) or np.isnan(r).any() or np.any(r[:, 0] > r[:, 1]):
                raise DataError("curve_range_deg must be (50, 2) low <= high, no NaN")
        for name, arr in (("gains", self.gains), ("curve_means_deg", self.curve_means_deg),
                          ("control_means_deg", self.control_means_deg)):
            if not np.isfinite(arr).all():
                raise DataError(f"map {name} contain NaN or inf")

    @property
    def control_indices(self) -> NDArray[np.intp]:
        return np.array([hand.curve_index(c) for c in self.controls], dtype=np.intp)

    @property
    def piecewise(self) -> bool:
        """Whether the map has hinge terms (a piecewise-linear map)."""
        return self.knots_deg is not None

    def feature_gains(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The map as one affine map of its features: ``curves = bias + gains_f @ f`` with
        ``f = (controls, max(0, controls - knots))`` (the hinge half only for a
        piecewise-linear map). Returns ``gains_f`` (50, k + h), ``bias`` (50,) and the
        knots (h,), h = k or 0."""
        if self.knots_deg is None or self.hinge_gains is None:
            bias: FloatArray = self.curve_means_deg - self.gains @ self.control_means_deg
            return self.gains.copy(), bias, np.zeros(0)
        at_means = np.maximum(self.control_means_deg - self.knots_deg, 0.0)
        bias = (self.curve_means_deg - self.gains @ self.control_means_deg
                - self.hinge_gains @ at_means)
        return (np.hstack([self.gains, self.hinge_gains]), bias,
                np.asarray(self.knots_deg, dtype=np.float64).copy())

    def predict(self, controls_deg: FloatArray) -> FloatArray:
        """(n, k) control values -> (n, 50) curves, clipped to :meth:`output_range_deg`
        but not to the joint limits (see :class:`Expander`)."""
        x = np.asarray(controls_deg, dtype=np.float64)
        out: FloatArray = self.curve_means_deg + (x - self.control_means_deg) @ self.gains.T
        if self.knots_deg is not None and self.hinge_gains is not None:
            out += (np.maximum(x - self.knots_deg, 0.0)
                    - np.maximum(self.control_means_deg - self.knots_deg, 0.0)
                    ) @ self.hinge_gains.T
        if self.curve_range_deg is not None:
            np.clip(out, self.curve_range_deg[:, 0], self.curve_range_deg[:, 1], out=out)
        return out

    def output_range_deg(self) -> FloatArray:
        """(50, 2) the range each curve's output is clipped to; -inf/inf where none."""
        if self.curve_range_deg is None:
            return np.tile([-np.inf, np.inf], (50, 1))
        return self.curve_range_deg.copy()

    def to_toml(self) -> str:
        """The map as a commented, human-readable TOML document."""
        q = json.dumps
        lines = [
            "# handrig linear map (vocabulary convention: degrees, flexion positive).",
            "# For every curve:",
            "#   curve = mean_deg + sum over controls c of gains[c] * (c - control_means_deg[c])",
            "# gains are degrees of the curve per degree of the control; a curve without",
            "# gains is held at its mean. Written by `handrig fit-map`.",
            *(["# Piecewise-linear: above knots_deg[c] the slope on c changes by",
               "# hinge_gains[c], adding hinge_gains[c] * (max(0, c - knots_deg[c])",
               "#   - max(0, control_means_deg[c] - knots_deg[c]))."] if self.piecewise else []),
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
        if self.knots_deg is not None:
            lines.append("# piecewise-linear: where each control's slope changes")
            lines.append(f"knots_deg = [{', '.join(_num(v) for v in self.knots_deg)}]")
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
            if self.hinge_gains is not None:
                hg = ", ".join(f"{c} = {_num(self.hinge_gains[i, j], 5)}"
                               for j, c in enumerate(self.controls)
                               if abs(self.hinge_gains[i, j]) >= 5e-6)
                if hg:
                    lines.append(f"hinge_gains = {{ {hg} }}")
            if self.curve_range_deg is not None and np.isfinite(self.curve_range_deg[i]).all():
                lo, hi = self.curve_range_deg[i]
                lines.append(f"range_deg = [{_num(lo)}, {_num(hi)}]")
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
        crange = np.tile([-np.inf, np.inf], (50, 1))
        hinge = np.zeros((50, k))
        for i, name in enumerate(hand.CURVE_NAMES):
            entry = mf.curves[name]
            means[i] = entry.mean_deg
            for c, g in entry.gains.items():
                gains[i, mf.controls.index(c)] = g
            for c, g in entry.hinge_gains.items():
                hinge[i, mf.controls.index(c)] = g
            if entry.fit_rms_deg is not None:
                fit[i] = entry.fit_rms_deg
            if entry.range_deg is not None:
                crange[i] = entry.range_deg
        rng = None if mf.control_range_deg is None else np.array(mf.control_range_deg,
                                                                  dtype=np.float64)
        try:
            lm = cls(
                controls=mf.controls, control_means_deg=np.array(mf.control_means_deg),
                curve_means_deg=means, gains=gains, method=mf.method, trained_on=mf.trained_on,
                profile=mf.profile, frames=mf.frames, fps=mf.fps, description=mf.description,
                fit_rms_deg=None if np.isnan(fit).any() else fit, control_range_deg=rng,
                curve_range_deg=crange if np.isfinite(crange).any() else None,
                fitting=mf.fitting, evaluation=mf.evaluation,
                knots_deg=None if mf.knots_deg is None else np.array(mf.knots_deg,
                                                                     dtype=np.float64),
                hinge_gains=None if mf.knots_deg is None else hinge,
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
        lo, hi = self.control_range_deg[:, 0], self.control_range_deg[:, 1]
        out: FloatArray = np.abs(self.gains) @ (hi - lo)
        if self.knots_deg is not None and self.hinge_gains is not None:
            out = out + np.abs(self.hinge_gains) @ (np.maximum(hi - self.knots_deg, 0.0)
                                                    - np.maximum(lo - self.knots_deg, 0.0))
        return out

    def check_plausible(self, source: str = "<map>") -> list[str]:
        """Raise ConfigError (naming ``source`` and the key) for an implausible map;
        return warnings for doubtful values (``load`` issues them as :class:`MapWarning`)."""
        idx = set(int(i) for i in self.control_indices)
        tables = [("gains", self.gains)]
        if self.hinge_gains is not None:
            tables.append(("hinge_gains", self.hinge_gains))
        for key, table in tables:
            for i, name in enumerate(hand.CURVE_NAMES):
                j = int(np.argmax(np.abs(table[i])))
                g = float(table[i, j])
                if i not in idx and abs(g) > MAX_GAIN:
                    raise ConfigError(
                        "gain is implausible: no curve moves that many degrees per degree"
                        " of a control (refit the map with handrig fit-map)",
                        file=source, key=f"curves.{name}.{key}.{self.controls[j]}", value=g,
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
    hinge_gains: dict[str, float] = field(default_factory=dict)
    fit_rms_deg: float | None = None
    range_deg: tuple[float, float] | None = None


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
    knots_deg: tuple[float, ...] | None = None

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
            if entry.range_deg is not None and not entry.range_deg[0] <= entry.range_deg[1]:
                raise ConfigError("inverted range: low must not exceed high",
                                  key=f"curves.{name}.range_deg", value=list(entry.range_deg))
            for c in entry.gains:
                if c not in self.controls:
                    raise ConfigError(
                        "gain on a name that is not a control", key=f"curves.{name}.gains.{c}",
                        allowed=", ".join(self.controls),
                    )
            for c in entry.hinge_gains:
                if c not in self.controls:
                    raise ConfigError(
                        "hinge gain on a name that is not a control",
                        key=f"curves.{name}.hinge_gains.{c}", allowed=", ".join(self.controls))
                if self.knots_deg is None:
                    raise ConfigError(
                        "a hinge gain needs the map's knots_deg (one knot per control)",
                        key=f"curves.{name}.hinge_gains.{c}", allowed="knots_deg = [...]")
        if self.knots_deg is not None and len(self.knots_deg) != len(self.controls):
            raise ConfigError(f"needs one knot per control ({len(self.controls)})",
                              key="knots_deg", value=list(self.knots_deg))
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
