"""Conditioning a capture before anything is learnt from it: its calibration offsets.

A mocap suit's calibration can leave a constant offset on a joint angle: the reference
capture's right index PIP reads -20 deg (hyperextension no finger has) in 1 % of its
frames and below 0 in 45 %, while the middle finger's PIP rarely goes below 0. An offset
is not motion; learnt as it is, it goes into every puppet.

:func:`find_offsets` finds the per-curve offsets from each curve's own distribution
against its anatomical range (:func:`handrig.hand.curve_limits_deg`): the smallest shift
that brings the curve's :data:`TAIL_PCT` and ``100 - TAIL_PCT`` percentiles inside the
range (0 when they are already inside; a percentile, not the extreme, so that a glitch
or a rare frame does not set the offset). Curves that the capture device copies exactly
(the Perception Neuron suit copies PIP to DIP) share one offset, the largest any of them
needs, so a copy stays a copy. Offsets are rounded to 0.1 deg.

An offset moves neither a curve's range nor its standard deviation nor its correlation
with any other curve, so the analysis of Jörg & O'Sullivan (ranges, rmsd1/rmsd2, the
reduction counts) is the same on conditioned curves: :func:`analysis_unchanged` checks
it. The offsets found on a capture are recorded in its profile's ``[calibration]`` table
(``config/profiles/perception_neuron.toml``) with how they were found, and applied when
a capture is loaded in the vocabulary convention (:func:`handrig.offline.mocap.load_curves`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.errors import DataError
from handrig.offline.analysis import Thresholds, analyze, rmsd_matrices

FloatArray = NDArray[np.float64]
TAIL_PCT = 0.5
"""The percentile (and its mirror) that must lie inside the anatomical range."""
HOW = (f"per curve, the smallest shift that brings its {TAIL_PCT:g}th and"
       f" {100 - TAIL_PCT:g}th percentiles inside the anatomical range of handrig/hand.py;"
       " curves the device copies exactly share the largest; rounded to 0.1 deg"
       " (handrig.offline.conditioning.find_offsets)")
"""How :func:`find_offsets` works, in one line for a profile's ``[calibration]`` table."""


def find_offsets(curves: FloatArray, limits_deg: FloatArray | None = None, *,
                 tail_pct: float = TAIL_PCT) -> FloatArray:
    """Per-curve offsets (deg, shape (50,)) to add to ``curves`` (frames x 50, vocabulary
    convention) so that each stays inside ``limits_deg`` ((50, 2); None: the anatomical
    ranges) but for ``tail_pct`` % of frames at either end (see the module docstring)."""
    y = np.asarray(curves, dtype=np.float64)
    if y.ndim != 2 or y.shape[1] != len(hand.CURVE_NAMES) or y.shape[0] < 2:
        raise DataError(f"finding offsets needs frames x 50 curves, got {y.shape}")
    if not np.isfinite(y).all():
        raise DataError("curves contain NaN/inf: repair them first (--despike)")
    if not 0.0 <= tail_pct < 50.0:
        raise DataError(f"tail percentile must be in [0, 50), got {tail_pct}")
    lim = hand.curve_limits_deg() if limits_deg is None else np.asarray(limits_deg, float)
    lo = np.percentile(y, tail_pct, axis=0)
    hi = np.percentile(y, 100.0 - tail_pct, axis=0)
    need_up = np.maximum(lim[:, 0] - lo, 0.0)
    need_down = np.maximum(hi - lim[:, 1], 0.0)
    # a curve wider than its range: centre it rather than push one end out
    off: FloatArray = np.where((need_up > 0) & (need_down > 0), (need_up - need_down) / 2.0,
                   need_up - need_down)
    for members in copy_groups(y):
        pick = members[int(np.argmax(np.abs(off[members])))]
        off[members] = off[pick]
    out: FloatArray = np.asarray(np.round(off, 1) + 0.0, dtype=np.float64)
    return out


def copy_groups(curves: FloatArray) -> list[list[int]]:
    """Groups (two or more curve indices) of moving curves that are exact copies."""
    y = np.asarray(curves, dtype=np.float64)
    groups: list[list[int]] = []
    seen: set[int] = set()
    for i in range(y.shape[1]):
        if i in seen or np.ptp(y[:, i]) == 0.0:
            continue
        same = [j for j in range(i + 1, y.shape[1]) if np.array_equal(y[:, i], y[:, j])]
        if same:
            groups.append([i, *same])
            seen.update(same)
    return groups


def outside_fraction(curves: FloatArray, limits_deg: FloatArray | None = None
                     ) -> FloatArray:
    """Per curve (50,), the fraction of frames outside ``limits_deg`` (None: anatomical)."""
    y = np.asarray(curves, dtype=np.float64)
    lim = hand.curve_limits_deg() if limits_deg is None else np.asarray(limits_deg, float)
    out: FloatArray = ((y < lim[:, 0]) | (y > lim[:, 1])).mean(axis=0)
    return out


def analysis_unchanged(curves: FloatArray, offsets_deg: FloatArray,
                       thresholds: Thresholds | None = None) -> tuple[bool, float]:
    """Whether the paper's analysis of ``curves + offsets_deg`` equals that of ``curves``
    (the same constant curves, links and DOFs left at every stage), and the largest
    change of any range or rmsd it saw (float rounding only)."""
    y = np.asarray(curves, dtype=np.float64)
    yc = y + np.asarray(offsets_deg, dtype=np.float64)
    th = thresholds or Thresholds()
    a, b = analyze(y, th), analyze(yc, th)
    same = all(sa.dofs_left == sb.dofs_left and sa.constant == sb.constant
               and [(lk.dependent, lk.controller, lk.slope) for lk in sa.links]
               == [(lk.dependent, lk.controller, lk.slope) for lk in sb.links]
               for sa, sb in zip(a.stages, b.stages, strict=True))
    r1, r2 = rmsd_matrices(y)
    c1, c2 = rmsd_matrices(yc)
    moved = max(float(np.max(np.abs(np.ptp(y, axis=0) - np.ptp(yc, axis=0)))),
                float(np.max(np.abs(r1 - c1))), float(np.max(np.abs(r2 - c2))))
    return same and len(a.stages) == len(b.stages), moved
