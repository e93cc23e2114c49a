"""Reconstruction error of maps: per curve, per hand and overall RMS, in degrees.

:func:`cross_validate` measures how well each fitting method reconstructs *unseen*
motion: leave one segment out (for the reference capture, its README's gesture clips),
fit on the rest, predict the held-out segment through the clamping :class:`Expander`,
and pool the held-out errors.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.config import JointLimits
from handrig.errors import DataError
from handrig.expand import Expander
from handrig.maps import LinearMap, fit_map

FloatArray = NDArray[np.float64]
_RI = slice(0, hand.CURVES_PER_HAND)
_LE = slice(hand.CURVES_PER_HAND, 2 * hand.CURVES_PER_HAND)


@dataclass(frozen=True)
class Errors:
    """RMS errors in degrees: ``per_curve`` (50,), ``ri``, ``le`` and ``overall``."""

    per_curve: FloatArray
    ri: float
    le: float
    overall: float

    def to_json(self) -> dict[str, object]:
        return {
            "ri_rms_deg": round(self.ri, 4), "le_rms_deg": round(self.le, 4),
            "overall_rms_deg": round(self.overall, 4),
            "per_curve_rms_deg": {n: round(float(v), 4)
                                  for n, v in zip(hand.CURVE_NAMES, self.per_curve, strict=True)},
        }


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
