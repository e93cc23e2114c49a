"""Validation that predicts unseen takes: whole stretches of time held out with a gap,
and the other hand as an unseen hand.

Leave-one-clip-out (:mod:`handrig.offline.evaluation`) tests on frames that sit next to
training frames in time: a held-out clip's neighbours share its calibration offsets and
its drifts, and its calm frames look like theirs. On two unseen takes of the same device
that scoring did not predict what a change did (issue 42: the calm-unseen split said
-0.64 deg, an unseen calm take said +0.44). The splits here hold out more:

* ``blocked``: the capture cut into :data:`BLOCKS` contiguous blocks of time; each block is
  tested on maps fit on the frames more than :data:`GAP_S` seconds away from it (the frames
  within the gap are in neither), so no training frame is a neighbour of a test frame;
* ``blocked-calm``: the calm frames (:func:`~handrig.offline.evaluation.calm_frames`) of
  each held-out block, the same maps;
* ``blocked-offset``: each held-out block with every control off by
  :data:`~handrig.offline.evaluation.OFFSET_DEG` (as the ``offset`` split);
* ``other-hand``: the maps fit on the training frames as they are, tested on the held-out
  block mirrored (:func:`handrig.hand.mirror_pose`: the left hand's curves read as the
  right's, and back), so a right-glove map drives the right hand from the left hand's
  controls and is scored against the left hand's own curves. An unseen hand: other sensors,
  other calibration offsets, a hand that mostly rests.

Every figure is pooled over the folds, with the spread across them (each fold's own RMS:
their standard deviation and the worst fold), so a difference smaller than the spread is
read as none.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np

from handrig.errors import DataError
from handrig.offline.evaluation import (
    CURVE_GROUPS,
    OFFSET_DEG,
    Errors,
    Mask,
    Split,
    group_rms,
)

BLOCKS = 5
"""Contiguous blocks of time, each held out in turn (the reference: about 9 s each)."""
GAP_S = 2.0
"""Seconds on each side of a held-out block that neither train nor test."""


def blocked_folds(n_frames: int, fps: float, count: int = BLOCKS, gap_s: float = GAP_S
                  ) -> tuple[tuple[Mask, Mask], ...]:
    """``count`` (train, test) frame masks: test is one contiguous block of the
    ``n_frames``, train every frame more than ``gap_s`` seconds (``round(gap_s * fps)``
    frames) before or after it. DataError when a block or a training set would be empty."""
    if not fps > 0:
        raise DataError(f"the blocked split needs the frame rate, got {fps}")
    if gap_s < 0:
        raise DataError(f"the gap must be at least 0 s, got {gap_s}")
    if count < 2 or count > n_frames // 2:
        raise DataError(f"need 2 .. {n_frames // 2} blocks for {n_frames} frames, got {count}")
    gap = round(gap_s * fps)
    edges = np.linspace(0, n_frames, count + 1).round().astype(int)
    folds = []
    for a, b in itertools.pairwise(edges):
        test = np.zeros(n_frames, dtype=bool)
        test[a:b] = True
        train = np.ones(n_frames, dtype=bool)
        train[max(0, a - gap):b + gap] = False
        if train.sum() < 2:
            raise DataError(f"a gap of {gap_s:g} s leaves no training frames around block"
                            f" {a}..{b - 1} of {n_frames}: use fewer blocks or a shorter gap")
        folds.append((train, test))
    return tuple(folds)


def blocked_splits(n_frames: int, fps: float, calm: Mask, count: int = BLOCKS,
                   gap_s: float = GAP_S) -> list[Split]:
    """The splits of the module docstring, for a capture of ``n_frames`` with ``calm``
    frames (a block without calm frames is left out of ``blocked-calm``)."""
    if calm.shape != (n_frames,):
        raise DataError(f"calm needs one flag per frame ({n_frames}), got {calm.shape}")
    folds = blocked_folds(n_frames, fps, count, gap_s)
    how = f"{count} blocks of time, {gap_s:g} s gap"
    out = [Split("blocked", f"{how}: each held-out block", folds)]
    calm_folds = tuple((tr, te & calm) for tr, te in folds if (te & calm).any())
    if calm_folds:
        out.append(Split("blocked-calm", f"{how}: the calm frames of each held-out block",
                         calm_folds))
    out.append(Split("blocked-offset", f"{how}: each held-out block, every control off by"
                     f" {OFFSET_DEG:g} deg", folds, OFFSET_DEG))
    out.append(Split("other-hand", f"{how}: each held-out block mirrored (maps fit on one"
                     " hand, tested on the other)", folds, mirrored=True))
    return out


def spread(folds: Sequence[float]) -> tuple[float, float]:
    """(standard deviation, worst) of the folds' RMS figures; (0, 0) with none."""
    if not folds:
        return 0.0, 0.0
    arr = np.asarray(folds, dtype=np.float64)
    return float(arr.std()), float(arr.max())


def best_methods(results: dict[str, dict[str, Errors]]) -> dict[str, str]:
    """Per split, the method with the lowest pooled right-hand RMS."""
    return {sp: min(res, key=lambda k: res[k].ri) for sp, res in results.items() if res}


def validation_table(results: dict[str, dict[str, Errors]], splits: Sequence[Split]
                     ) -> list[str]:
    """Aligned text: split, method, right hand pooled RMS with its spread across folds
    (sd, worst fold), its curve groups and clamp%, then the left hand's pooled RMS."""
    groups = tuple(CURVE_GROUPS)
    head = " ".join(f"{g:>7}" for g in groups)
    lines = [f"  {'split':<15} {'method':<9} {'right':>6} {'+-sd':>5} {'worst':>6} {head}"
             f" {'clamp%':>6}   {'left':>6} {'+-sd':>5}"]
    for sp in splits:
        for method, err in results[sp.name].items():
            sd, worst = spread(err.ri_folds)
            le_sd, _ = spread(err.le_folds)
            g = group_rms(err, "ri")
            pct = "-" if err.ri_clamped is None else f"{100 * err.ri_clamped:.2f}"
            lines.append(f"  {sp.name:<15} {method:<9} {err.ri:>6.2f} {sd:>5.2f} {worst:>6.2f} "
                         + " ".join(f"{g[k]:>7.2f}" for k in groups)
                         + f" {pct:>6}   {err.le:>6.2f} {le_sd:>5.2f}")
    return lines


def validation_json(results: dict[str, dict[str, Errors]], splits: Sequence[Split]
                    ) -> dict[str, object]:
    """The results as JSON-ready values, per split and method."""
    out: dict[str, object] = {}
    for sp in splits:
        methods: dict[str, object] = {}
        for k, v in results[sp.name].items():
            sd, worst = spread(v.ri_folds)
            methods[k] = {
                "ri_rms_deg": round(v.ri, 4), "le_rms_deg": round(v.le, 4),
                "ri_fold_sd_deg": round(sd, 4), "ri_worst_fold_deg": round(worst, 4),
                "ri_folds_rms_deg": [round(f, 4) for f in v.ri_folds],
                "le_folds_rms_deg": [round(f, 4) for f in v.le_folds],
                **v.clamped_json(),
                "ri_groups_rms_deg": {g: round(x, 4) for g, x in group_rms(v).items()},
            }
        out[sp.name] = {"description": sp.description, "methods": methods}
    return out

