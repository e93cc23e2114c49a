"""Reconstruction error of maps: per curve, per hand and overall RMS, in degrees.

:func:`cross_validate` measures how well each fitting method reconstructs *unseen*
motion: leave one segment out (for the reference capture, its README's gesture clips),
fit on the rest, predict the held-out segment through the clamping :class:`Expander`,
and pool the held-out errors.

:func:`out_of_regime` measures it on motion unlike the training data, split by split
(:func:`reference_splits` for the reference capture, :func:`block_splits` for others):

* ``clips``: leave one clip out (the unseen-gesture figure);
* ``kinds``: train on two kinds of gesture, test on the third (``mocap.REFERENCE_KINDS``);
* ``calm``: the calm frames of each held-out clip (the hand still, near rest:
  :func:`calm_frames`), maps fit on the other clips;
* ``calm-unseen``: the same frames, maps fit on the other clips' moving frames only
  (the map has never seen the hand at rest);
* ``offset``: held-out clips with every control off by ``OFFSET_DEG`` (random signs per
  control, ``OFFSET_DRAWS`` patterns per clip, fixed seed): a glove calibration that is
  off, or a rest pose of the controls that the capture never held. The truth is the
  capture's own curves.

The blocked splits that hold out whole stretches of time with a gap, and the other hand,
are built in :mod:`handrig.offline.validation` and run through the same
:func:`out_of_regime` (a :class:`Split` may test the mirrored frames; each result keeps
every fold's own RMS, the spread of the pooled figure).

Beside each RMS error, the fraction of the hand's predicted values that the joint limits
clamped (``clamp%``: the map asked for a pose outside the joints; what a run counts as
pose clamps).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.config.loading import JointLimits
from handrig.errors import DataError
from handrig.offline import mocap
from handrig.offline.fitting import block_groups, fit_map
from handrig.pose.expand import Expander
from handrig.pose.maps import LinearMap

FloatArray = NDArray[np.float64]
_RI = slice(0, hand.CURVES_PER_HAND)
_LE = slice(hand.CURVES_PER_HAND, 2 * hand.CURVES_PER_HAND)


@dataclass(frozen=True)
class Errors:
    """RMS errors in degrees: ``per_curve`` (50,), ``ri``, ``le`` and ``overall``;
    ``ri_clamped``/``le_clamped``: the fraction of the hand's predicted values that the
    joint limits clamped (the map asked for a pose outside the joints), when known."""

    per_curve: FloatArray
    ri: float
    le: float
    overall: float
    ri_clamped: float | None = None
    le_clamped: float | None = None
    ri_folds: tuple[float, ...] = ()
    le_folds: tuple[float, ...] = ()
    """Each fold's own right/left RMS (the spread of the pooled figure), when known."""

    def to_json(self) -> dict[str, object]:
        return {
            "ri_rms_deg": round(self.ri, 4), "le_rms_deg": round(self.le, 4),
            "overall_rms_deg": round(self.overall, 4),
            **self.clamped_json(),
            "per_curve_rms_deg": {n: round(float(v), 4)
                                  for n, v in zip(hand.CURVE_NAMES, self.per_curve, strict=True)},
        }


    def clamped_json(self) -> dict[str, float]:
        if self.ri_clamped is None or self.le_clamped is None:
            return {}
        return {"ri_clamped_fraction": round(self.ri_clamped, 6),
                "le_clamped_fraction": round(self.le_clamped, 6)}


def clamped_fractions(map_: LinearMap, curves: FloatArray, limits: JointLimits | None = None
                      ) -> tuple[float, float]:
    """Right and left hand: the fraction of values of the map's output for ``curves``'
    controls (clipped to the map's own range) that lie outside the joint limits."""
    lim = (hand.curve_limits_deg() if limits is None
           else np.array([limits.of(n) for n in hand.CURVE_NAMES], dtype=np.float64))
    raw = map_.predict(curves[:, map_.control_indices])
    out = (raw < lim[:, 0]) | (raw > lim[:, 1])
    return float(out[:, _RI].mean()), float(out[:, _LE].mean())


def rms_errors(pred: FloatArray, truth: FloatArray) -> Errors:
    """RMS of ``pred - truth`` (frames x 50) per curve, per hand and over all curves."""
    if pred.shape != truth.shape:
        raise DataError(f"prediction {pred.shape} and truth {truth.shape} differ in shape")
    sq = (pred - truth) ** 2
    return Errors(
        per_curve=np.sqrt(sq.mean(axis=0)), ri=float(np.sqrt(sq[:, _RI].mean())),
        le=float(np.sqrt(sq[:, _LE].mean())), overall=float(np.sqrt(sq.mean())),
    )


def predict(map_: LinearMap, curves: FloatArray, limits: JointLimits | None = None
            ) -> FloatArray:
    """What the runtime would output for ``curves``' control columns (clamped)."""
    ex = Expander(map_, limits)
    return ex.expand_many(np.ascontiguousarray(curves[:, map_.control_indices]))


def contiguous_folds(n_frames: int, count: int) -> list[tuple[int, int]]:
    """``count`` contiguous (start, stop) segments covering ``n_frames``."""
    if count < 2 or count > n_frames // 2:
        raise DataError(f"need 2 .. {n_frames // 2} folds for {n_frames} frames, got {count}")
    edges = np.linspace(0, n_frames, count + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in itertools.pairwise(edges)]


def cross_validate(
    curves: FloatArray,
    controls: Sequence[str],
    folds: Sequence[tuple[int, int]],
    methods: Sequence[str] = ("ridge", "huber", "paper", "mean"),
    limits: JointLimits | None = None,
) -> dict[str, Errors]:
    """Leave-one-fold-out RMS errors of each method on ``curves`` (frames x 50, vocabulary)."""
    y = np.asarray(curves, dtype=np.float64)
    out: dict[str, Errors] = {}
    for method in methods:
        preds = []
        truth = []
        for start, stop in folds:
            train = np.concatenate([y[:start], y[stop:]])
            m = fit_map(train, controls, method)
            preds.append(predict(m, y[start:stop], limits))
            truth.append(y[start:stop])
        out[method] = rms_errors(np.concatenate(preds), np.concatenate(truth))
    return out


CALM_SPEED_DEG_S = 6.0
"""A frame is calm when the right hand's curves move slower than this (RMS over its 25
curves, smoothed over 5 frames)."""
CALM_MIN_S = 0.25
"""... for at least this long."""
OFFSET_DEG = 2.0
OFFSET_SEED = 0
OFFSET_DRAWS = 8
"""Sign patterns of the offset per held-out fold (pooled), so the figure is not one draw's."""
REGIME_METHODS: tuple[str, ...] = ("mean", "paper", "ridge", "robust", "piecewise")
CURVE_GROUPS: dict[str, tuple[str, ...]] = {
    "thumb": ("ThumbCMCx", "ThumbCMCy", "ThumbCMCz", "ThumbMCPz", "ThumbIPz"),
    "MCP": tuple(f"{f}MCP{a}" for f in ("Index", "Middle", "Ring", "Pinky") for a in "xyz"),
    "PIP/DIP": tuple(f"{f}{j}y" for f in ("Index", "Middle", "Ring", "Pinky")
                     for j in ("PIP", "DIP")),
}
"""Curve groups of one hand (without the ri/le prefix) for the per-group figures."""

Mask = NDArray[np.bool_]


@dataclass(frozen=True)
class Split:
    """One way of holding data out: ``folds`` are (train, test) frame masks."""

    name: str
    description: str
    folds: tuple[tuple[Mask, Mask], ...]
    offset_deg: float = 0.0
    mirrored: bool = False
    """Test on the other hand: the held-out frames mirrored (``hand.mirror_pose``: the
    left hand's curves read as the right's and back), the maps fit on the frames as they
    are."""


def group_rms(err: Errors, side: str = "ri") -> dict[str, float]:
    """RMS error (deg) of each :data:`CURVE_GROUPS` group of hand ``side``."""
    out = {}
    for g, names in CURVE_GROUPS.items():
        idx = [hand.curve_index(side + n) for n in names]
        out[g] = float(np.sqrt(np.mean(err.per_curve[idx] ** 2)))
    return out


def calm_frames(curves: FloatArray, fps: float, groups: NDArray[np.intp], *,
                speed_deg_s: float = CALM_SPEED_DEG_S, min_s: float = CALM_MIN_S) -> Mask:
    """Frames where the right hand is still (see :data:`CALM_SPEED_DEG_S`), within each
    group (clip boundaries are discontinuities, never differentiated across)."""
    y = np.asarray(curves, dtype=np.float64)[:, :hand.CURVES_PER_HAND]
    calm = np.zeros(y.shape[0], dtype=bool)
    run = max(1, round(min_s * fps))
    for g in np.unique(groups):
        idx = np.nonzero(groups == g)[0]
        if len(idx) < 3:
            continue
        v = np.gradient(y[idx], axis=0) * fps
        speed = np.sqrt((v ** 2).mean(axis=1))
        speed = np.convolve(np.pad(speed, 2, mode="edge"), np.ones(5) / 5, mode="valid")
        still = speed < speed_deg_s
        edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(np.int8), [0]])))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            if b - a >= run:
                calm[idx[a:b]] = True
    return calm


def _leave_one_out(groups: NDArray[np.intp]) -> list[tuple[Mask, Mask]]:
    return [(groups != g, groups == g) for g in np.unique(groups)]


def _regime_splits(groups: NDArray[np.intp], calm: Mask, unit: str,
                   kinds: NDArray[np.intp] | None, kind_names: Sequence[str]) -> list[Split]:
    loo = _leave_one_out(groups)
    out = [Split("clips", f"leave one {unit} out", tuple(loo))]
    if kinds is not None:
        folds = tuple((kinds != k, kinds == k) for k in np.unique(kinds))
        out.append(Split("kinds", "train on two kinds of gesture, test on the third ("
                         + ", ".join(kind_names) + ")", folds))
    calm_folds = tuple((tr, te & calm) for tr, te in loo if (te & calm).any())
    if calm_folds:
        out.append(Split("calm", f"calm frames of each held-out {unit}", calm_folds))
        out.append(Split("calm-unseen", f"calm frames of each held-out {unit}, fit without"
                         " any calm frame", tuple((tr & ~calm, te) for tr, te in calm_folds)))
    out.append(Split("offset", f"leave one {unit} out, every control off by"
                     f" {OFFSET_DEG:g} deg", tuple(loo), OFFSET_DEG))
    return out


def reference_splits(curves: FloatArray, fps: float) -> tuple[list[Split], NDArray[np.intp]]:
    """The out-of-regime splits of the reference capture, and its clip labels."""
    groups = mocap.reference_clip_labels()
    if len(groups) != len(curves):
        raise DataError(f"the reference has {len(groups)} frames, got {len(curves)}")
    kind_names = sorted(set(mocap.REFERENCE_KINDS.values()))
    kinds = np.array([kind_names.index(mocap.REFERENCE_KINDS[mocap.REFERENCE_CLIPS[g][0]])
                      for g in groups], dtype=np.intp)
    calm = calm_frames(curves, fps, groups)
    return _regime_splits(groups, calm, "clip", kinds, kind_names), groups


def block_splits(curves: FloatArray, fps: float, count: int
                 ) -> tuple[list[Split], NDArray[np.intp]]:
    """The same splits for a file without known clips: ``count`` contiguous blocks, no
    gesture kinds."""
    contiguous_folds(len(curves), count)  # validates count
    groups = block_groups(len(curves), count)
    calm = calm_frames(curves, fps, groups)
    return _regime_splits(groups, calm, "block", None, ()), groups


def out_of_regime(
    curves: FloatArray, controls: Sequence[str], splits: Sequence[Split],
    groups: NDArray[np.intp], methods: Sequence[str] = REGIME_METHODS,
    limits: JointLimits | None = None,
) -> dict[str, dict[str, Errors]]:
    """``{split: {method: Errors}}``: held-out errors pooled over each split's folds.

    The ``robust`` method's own cross-validation uses ``groups`` of the training frames.
    Maps are fit once per (method, training set) and shared between splits. A
    ``mirrored`` split tests ``hand.mirror_pose`` of the held-out frames (the other hand);
    each :class:`Errors` keeps its folds' own RMS (``ri_folds``, ``le_folds``).
    """
    y = np.asarray(curves, dtype=np.float64)
    y_other = hand.mirror_pose(y)
    cache: dict[tuple[str, bytes], LinearMap] = {}
    out: dict[str, dict[str, Errors]] = {}
    for sp in splits:
        rng = np.random.default_rng(OFFSET_SEED)  # the same draws whatever splits come first
        draws = OFFSET_DRAWS if sp.offset_deg else 1
        offsets = [rng.choice([-1.0, 1.0], size=(draws, len(controls))) * sp.offset_deg
                   for _ in sp.folds]
        source = y_other if sp.mirrored else y
        res: dict[str, Errors] = {}
        for method in methods:
            preds, truth, clamped, folds = [], [], [], []
            for (train, test), offs in zip(sp.folds, offsets, strict=True):
                key = (method, np.packbits(train).tobytes())
                m = cache.get(key)
                if m is None:
                    m = fit_map(y[train], controls, method, groups=groups[train])
                    cache[key] = m
                fold_p, fold_t = [], []
                for off in offs:
                    seen = source[test].copy()
                    seen[:, m.control_indices] += off
                    fold_p.append(predict(m, seen, limits))
                    fold_t.append(source[test])
                    clamped.append(np.array(clamped_fractions(m, seen, limits)) * len(seen))
                folds.append(rms_errors(np.concatenate(fold_p), np.concatenate(fold_t)))
                preds += fold_p
                truth += fold_t
            err = rms_errors(np.concatenate(preds), np.concatenate(truth))
            ri_c, le_c = np.sum(clamped, axis=0) / sum(len(t) for t in truth)
            res[method] = replace(err, ri_clamped=float(ri_c), le_clamped=float(le_c),
                                  ri_folds=tuple(f.ri for f in folds),
                                  le_folds=tuple(f.le for f in folds))
        out[sp.name] = res
    return out


def regime_table(results: dict[str, dict[str, Errors]], splits: Sequence[Split]) -> list[str]:
    """The results as aligned text lines: split, method, each hand and its curve groups."""
    groups = tuple(CURVE_GROUPS)
    cols = " ".join(f"{g:>7}" for g in groups) + f" {'clamp%':>6}"
    lines = [f"  {'':<12} {'':<9} {'right hand':^39}   {'left hand':^39}",
             f"  {'split':<12} {'method':<9} {'all':>7} {cols}   {'all':>7} {cols}"]
    for sp in splits:
        for method, err in results[sp.name].items():
            cells = []
            for side, total, clamped in (("ri", err.ri, err.ri_clamped),
                                         ("le", err.le, err.le_clamped)):
                g = group_rms(err, side)
                pct = "-" if clamped is None else f"{100 * clamped:.2f}"
                cells.append(f"{total:>7.2f} " + " ".join(f"{g[k]:>7.2f}" for k in groups)
                             + f" {pct:>6}")
            lines.append(f"  {sp.name:<12} {method:<9} {cells[0]}   {cells[1]}")
    return lines


def write_error_figure(results: dict[str, dict[str, Errors]], path: str | Path, *,
                       title: str = "") -> Path:
    """PNG: RMS error per curve (deg), one panel per split, one bar per method."""
    from matplotlib.figure import Figure  # no pyplot: no global state (as report.py)

    p = Path(path)
    names = list(results)
    methods = list(next(iter(results.values())))
    fig = Figure(figsize=(14, 2.4 * len(names) + 0.6))
    axes = fig.subplots(len(names), 1, squeeze=False)
    x = np.arange(len(hand.CURVE_NAMES))
    width = 0.8 / max(1, len(methods))
    for ax, split in zip(axes[:, 0], names, strict=True):
        for i, method in enumerate(methods):
            ax.bar(x + (i - (len(methods) - 1) / 2) * width, results[split][method].per_curve,
                   width, label=f"{method} ({results[split][method].ri:.2f} right)")
        ax.set_ylabel(f"{split}\nRMS (deg)", fontsize=8)
        ax.set_xlim(-0.6, len(x) - 0.4)
        ax.axvline(hand.CURVES_PER_HAND - 0.5, color="0.5", lw=0.8)
        ax.legend(fontsize=7, ncol=len(methods), loc="upper right")
        ax.tick_params(axis="y", labelsize=7)
        ax.set_xticks(x)
        ax.set_xticklabels([])
    axes[-1, 0].set_xticklabels(hand.CURVE_NAMES, rotation=90, fontsize=6)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(p, dpi=100)
    except OSError as exc:
        raise DataError(f"cannot write figure {p}: {exc}") from None
    return p
