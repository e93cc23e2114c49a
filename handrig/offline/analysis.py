"""The analysis of Jörg & O'Sullivan, "Exploring the Dimensionality of Finger Motion", 4-5.

Section 4.1: range, mean and (population) standard deviation of each curve; a curve
whose range is below a threshold is *irrelevant* and becomes its mean.
Section 4.1: rmsd1 (positive slope) and rmsd2 (negative slope) between standardised
curves, for all pairs at once: with population std, for standardised a and b,
``rmsd1^2 = mean(a^2) + mean(b^2) - 2 mean(a b) = 2 - 2r`` and ``rmsd2^2 = 2 + 2r``
(r the correlation). A constant curve standardises to zeros (no NaN): its rmsd to
any other curve is 1.
Section 4.2 and 5.2: if rmsd1 or rmsd2 of a pair is below a threshold, the curve with
the smaller std follows the one with the larger by the mean/std-preserving maps
``a = +-(b - mean b) / std b * std a + mean a``. When several partners qualify, the one
with the largest std controls (5.2); a controller that is itself controlled passes its
own controller on, even if that pair's rmsd exceeds the threshold (5.2). Equal stds
(exact copies, e.g. a device that copies PIP to DIP) are ordered by canonical index:
the earlier curve controls.
Section 5: four steps, each a stage of Table 5: original; range < 1; range < 1 +
rmsd < 0.3; range < 5; range < 5 + rmsd < 0.5 (the range < 5 stage starts again from
the original curves, as in the paper: 50 - 19 = 31).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.errors import DataError

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Thresholds:
    """The four thresholds of section 5 (degrees for ranges, standardised units for rmsd)."""

    range_small_deg: float = 1.0
    rmsd_strict: float = 0.3
    range_large_deg: float = 5.0
    rmsd_loose: float = 0.5


@dataclass(frozen=True)
class Link:
    """A redundant curve: ``dependent`` follows ``controller`` (the end of its chain).

    ``partner`` is the direct partner whose rmsd was below the threshold (equal to
    ``controller`` unless the chain rule applied); ``slope`` is +1 (rmsd1) or -1 (rmsd2);
    ``rmsd`` is the metric of that slope between ``dependent`` and ``controller``.
    """

    dependent: str
    controller: str
    partner: str
    slope: int
    rmsd: float

    @property
    def metric(self) -> str:
        return "rmsd1" if self.slope > 0 else "rmsd2"


@dataclass(frozen=True)
class Stage:
    """One row of Table 5: which curves are constant, which follow which, DOFs left."""

    condition: str
    dofs_left: int
    constant: tuple[str, ...] = ()
    links: tuple[Link, ...] = ()

    @property
    def free(self) -> tuple[str, ...]:
        dep = {lk.dependent for lk in self.links}
        return tuple(n for n in hand.CURVE_NAMES if n not in self.constant and n not in dep)


@dataclass(frozen=True)
class Analysis:
    """Everything sections 4-5 compute for one motion (frames x 50 curves)."""

    n_frames: int
    range_deg: FloatArray
    mean_deg: FloatArray
    std_deg: FloatArray
    rmsd1: FloatArray
    rmsd2: FloatArray
    thresholds: Thresholds
    stages: tuple[Stage, ...]
    pairs_below: dict[str, dict[str, int]] = field(default_factory=dict)
    names: tuple[str, ...] = hand.CURVE_NAMES

    def to_json(self) -> dict[str, object]:
        """The JSON object of ``handrig analyze --json``."""
        return {
            "frames": self.n_frames,
            "curves": list(self.names),
            "stages": [{"condition": s.condition, "dofs_left": s.dofs_left} for s in self.stages],
            "pairs_below": self.pairs_below,
            "ranges_deg": {n: round(float(r), 6) for n, r in zip(self.names, self.range_deg,
                                                                   strict=True)},
            "links": {
                s.condition: [
                    {"dependent": lk.dependent, "controller": lk.controller,
                     "partner": lk.partner, "metric": lk.metric, "rmsd": round(lk.rmsd, 4)}
                    for lk in s.links
                ]
                for s in self.stages if s.links
            },
        }


def curve_stats(curves: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(range, mean, population std) of each column of ``curves`` (frames x k), degrees."""
    rng: FloatArray = np.ptp(curves, axis=0).astype(np.float64)
    return rng, curves.mean(axis=0), curves.std(axis=0)


def standardise(curves: FloatArray) -> FloatArray:
    """Each column minus its mean, over its population std; a constant column becomes 0."""
    mean = curves.mean(axis=0)
    std = curves.std(axis=0)
    constant = np.ptp(curves, axis=0) == 0.0
    safe = np.where(constant, 1.0, std)
    z: FloatArray = (curves - mean) / safe
    z[:, constant] = 0.0
    return z


def rmsd_matrices(curves: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(rmsd1, rmsd2), each k x k, between the standardised columns of ``curves``."""
    z = standardise(curves)
    gram = z.T @ z / z.shape[0]
    diag = np.diag(gram)
    base = diag[:, None] + diag[None, :]
    rmsd1 = np.sqrt(np.clip(base - 2.0 * gram, 0.0, None))
    rmsd2 = np.sqrt(np.clip(base + 2.0 * gram, 0.0, None))
    np.fill_diagonal(rmsd1, 0.0)
    return rmsd1, rmsd2


def _rank(std: FloatArray) -> NDArray[np.intp]:
    """Position of each curve in the order (std ascending, then later index first)."""
    k = std.shape[0]
    order = np.lexsort((-np.arange(k), std))  # last key is primary: std, then -index
    rank = np.empty(k, dtype=np.intp)
    rank[order] = np.arange(k)
    return rank


def find_links(
    active: NDArray[np.bool_], rmsd1: FloatArray, rmsd2: FloatArray, std: FloatArray,
    threshold: float, names: tuple[str, ...] = hand.CURVE_NAMES,
) -> tuple[Link, ...]:
    """The redundancy rules of 4.2 and 5.2 among the ``active`` curves (see module docs)."""
    rank = _rank(std)
    k = len(names)
    below1 = (rmsd1 < threshold) & active[:, None] & active[None, :]
    below2 = (rmsd2 < threshold) & active[:, None] & active[None, :]
    np.fill_diagonal(below1, False)
    np.fill_diagonal(below2, False)
    partner = np.full(k, -1, dtype=np.intp)
    slope = np.zeros(k, dtype=np.intp)
    for a in np.nonzero(active)[0]:
        cand = np.nonzero((below1[a] | below2[a]) & (rank > rank[a]))[0]
        if cand.size:
            b = cand[np.argmax(rank[cand])]
            partner[a] = b
            slope[a] = 1 if rmsd1[a, b] <= rmsd2[a, b] else -1
    links = []
    for a in np.nonzero(partner >= 0)[0]:
        root, sign = int(a), 1
        while partner[root] >= 0:  # ranks strictly increase along a chain: it ends
            sign *= int(slope[root])
            root = int(partner[root])
        rmsd = rmsd1[a, root] if sign > 0 else rmsd2[a, root]
        links.append(Link(names[a], names[root], names[partner[a]], sign, float(rmsd)))
    return tuple(links)


def analyze(
    curves: FloatArray, thresholds: Thresholds | None = None,
    names: tuple[str, ...] = hand.CURVE_NAMES,
) -> Analysis:
    """Sections 4-5 on ``curves`` (frames x 50, degrees): stats, rmsds, the five stages."""
    th = thresholds or Thresholds()
    x = np.asarray(curves, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != len(names):
        raise DataError(f"analysis needs frames x {len(names)} curves, got shape {x.shape}")
    if x.shape[0] < 2:
        raise DataError(f"analysis needs at least 2 frames, got {x.shape[0]}")
    if not np.isfinite(x).all():
        f, c = np.argwhere(~np.isfinite(x))[0]
        raise DataError(
            f"{names[c]} frame {f} is {x[f, c]}: NaN/inf cannot be analysed; pass --despike"
        )
    rng, mean, std = curve_stats(x)
    rmsd1, rmsd2 = rmsd_matrices(x)
    k = len(names)
    active_small = rng >= th.range_small_deg
    active_large = rng >= th.range_large_deg
    links_strict = find_links(active_small, rmsd1, rmsd2, std, th.rmsd_strict, names)
    links_loose = find_links(active_large, rmsd1, rmsd2, std, th.rmsd_loose, names)
    const_small = tuple(n for n, a in zip(names, active_small, strict=True) if not a)
    const_large = tuple(n for n, a in zip(names, active_large, strict=True) if not a)
    r1, r5 = f"{th.range_small_deg:g}", f"{th.range_large_deg:g}"
    stages = (
        Stage("original", k),
        Stage(f"range<{r1}", int(active_small.sum()), const_small),
        Stage(f"range<{r1} + rmsd<{th.rmsd_strict:g}",
              int(active_small.sum()) - len(links_strict), const_small, links_strict),
        Stage(f"range<{r5}", int(active_large.sum()), const_large),
        Stage(f"range<{r5} + rmsd<{th.rmsd_loose:g}",
              int(active_large.sum()) - len(links_loose), const_large, links_loose),
    )
    iu = np.triu_indices(k, 1)
    pair_active = active_small[iu[0]] & active_small[iu[1]]
    pairs_below = {
        f"{t:g}": {
            "rmsd1": int(((rmsd1[iu] < t) & pair_active).sum()),
            "rmsd2": int(((rmsd2[iu] < t) & pair_active).sum()),
        }
        for t in (th.rmsd_strict, th.rmsd_loose)
    }
    return Analysis(x.shape[0], rng, mean, std, rmsd1, rmsd2, th, stages, pairs_below, names)


def rebuild(curves: FloatArray, stage: Stage, names: tuple[str, ...] = hand.CURVE_NAMES
            ) -> FloatArray:
    """The curves as ``stage`` simplifies them: constants -> mean, links -> 4.2 maps."""
    x = np.asarray(curves, dtype=np.float64)
    out = x.copy()
    mean, std = x.mean(axis=0), x.std(axis=0)
    idx = {n: i for i, n in enumerate(names)}
    for n in stage.constant:
        out[:, idx[n]] = mean[idx[n]]
    for lk in stage.links:
        a, b = idx[lk.dependent], idx[lk.controller]
        zb = (x[:, b] - mean[b]) / std[b] if std[b] > 0 else np.zeros(x.shape[0])
        out[:, a] = lk.slope * zb * std[a] + mean[a]
    return out
