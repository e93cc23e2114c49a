"""Fit a robot hand's retarget table through its MJCF kinematics, and grade it.

The realtime step stays the linear table of :mod:`handrig.pose.retarget`
(``robot = clip(offset + G @ human50, low, high)``); what changes is how ``G`` and the
offsets are chosen. :func:`fit_retarget` chooses them offline so that, posed by
MuJoCo's forward kinematics (:mod:`sim.hand_kinematics`), the robot's fingertips
follow the human's:

* **fingertip positions** relative to the palm (the palm frame of
  :class:`sim.hand_kinematics.PalmFrame`), the human's carried onto the robot: each
  human tip relative to its digit's base on the palm, scaled by the robot digit's
  straight length over the human's, from the robot digit's base (the two hands'
  digits sit in different places on their palms: LEAP's fingers are 1.6 times a
  human's and spread twice as wide), over the reference capture (every
  :data:`CAPTURE_STEP`-th frame) and the human fist;
* **thumb-finger tip distances** at the human's pinches
  (:func:`sim.grasp_poses.pinch_poses`, where the human tips touch): the robot's
  thumb tip on the finger's (DexPilot's distance term, here fitted once offline
  rather than solved every frame);
* **fist closure**: at the human fist (:func:`sim.grasp_poses.fist_pose`) each robot
  finger reaches at least :data:`CLOSURE_GOAL` of its flexion range;
* **range**: over the capture frames, the degrees each joint's unclipped value lies
  past its range (a table that parks a joint at a limit for half the capture, as the
  coupled LEAP fit did with its index MCP, lets the fingers stand still).

Residuals are millimetres, each group weighted by :data:`WEIGHTS` over the square
root of its size (so a group's weight does not grow with its frame count); bounded
least squares (``scipy.optimize.least_squares``, trust region reflective) over
each joint's gains on the sources the table already gives it (the sign kept, the
magnitude in :data:`GAIN_BOUNDS`) and its offset (within its range). A thumb joint
never reads another thumb curve (LEAP's thumb base then fell with the thumb's
abduction channel it follows). A thumb flexion joint may read the pinching fingers'
flexion (``couple=True``, ``handrig retarget fit --couple``: :data:`COUPLING_CURVES`),
the DexPilot-style coupling that closes the thumb toward a finger as the finger
closes. The thumb's base (abduction, twist) is not coupled: in real hands the fingers'
flexion moves against it, and LEAP's base then turned against its own glove channel
(correlation -0.8 over the demo recording). A
**coupling** source (a thumb joint's source from a finger's curve, new or already in
the table) has a gain of either sign within :data:`COUPLING_BOUND`, pulled toward 0.
Joints without sources (ORCA's wrist) are left as they are. The clip is applied while
fitting: what the robot does.

:func:`grade` gives the figures ``handrig retarget check`` prints: fist closure per
finger, pinch gaps, and the fingertip error over the whole reference capture.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from handrig import hand
from handrig.errors import ConfigError
from handrig.pose.retarget import Retarget
from sim.grasp_poses import Pinch, fist_pose, pinch_poses
from sim.hand_kinematics import HumanTips, RobotTips

FloatArray = NDArray[np.float64]

CLOSURE_GOAL = 0.95  # fitted for; the check's target is 0.9
GAIN_BOUNDS = (0.2, 4.0)  # |gain| of a joint's own sources, degrees per degree
CAPTURE_STEP = 7  # every 7th reference frame (152 of 1063) in the fit
WEIGHTS = {"capture": 1.0, "fist": 1.0, "pinch": 10.0, "closure": 1000.0, "thumb": 0.3,
           "gain": 3.0, "clip": 1.0}
"""Per group: mm of residual per mm (closure: mm per unit of closure short of the goal;
thumb: a factor on the thumb tip's position terms, whose base sits elsewhere on each
robot's palm than on the human's, so its pinches count more than its place; gain: mm
per degree-per-degree a gain strays from 1 on its source, so a gain the tips hardly
see, such as a side-to-side joint's, stays near a degree for a degree instead of
wandering to a bound and amplifying the glove's noise; clip: mm per degree past a
joint's range)."""
COUPLING_CURVES = ("riIndexMCPy", "riIndexPIPy", "riMiddleMCPy", "riMiddlePIPy")
"""The finger curves a thumb joint may read with ``couple=True``: the pinching fingers'
MCP and PIP flexion (their DIP follows their PIP)."""
THUMB_GAIN_FLOOR = 0.7
"""With coupling, the floor of a thumb joint's |gain| on its own thumb curves (not
:data:`GAIN_BOUNDS`'): the coupling must not buy the pinches by parking the thumb (a
gain at 0.2 hardly follows the glove)."""
COUPLING_BOUND = 1.5
"""|gain| of a coupling source, degrees of thumb joint per degree of finger flexion."""
PINCH_STAGES = (0.1, 0.3, 1.0)
"""The pinch weight rises over three fits, each from the last one's answer: first the
tips and the fist, then the pinches pulled in (one fit at the full weight stalls in a
pose where the fingers bend to meet a thumb that cannot reach them)."""
FLEXION_SUFFIXES = ("MCPy", "PIPy", "DIPy")


@dataclass(frozen=True)
class GraspReport:
    """Figures of a retarget table through the robot's model (``handrig retarget check``).

    ``fist_closure``: per robot finger (named by the human digit it follows), the share
    of its flexion range (0 -> upper limit, summed over its flexion joints) reached at
    the human fist; ``pinch_gap_mm``: per pair (``thumb_index``...), the widest robot tip
    gap over the human's pinches of that pair; ``tip_error_mm``: median and p95 over
    the reference capture's frames and digits of |robot tip - scaled human tip|, and
    the median of each digit (``thumb_median``...); empty without a capture.
    """

    fist_closure: dict[str, float]
    pinch_gap_mm: dict[str, float]
    tip_error_mm: dict[str, float]
    fingers: dict[str, list[str]]
    scale: float

    def as_json(self) -> dict[str, object]:
        return dataclasses.asdict(self)


def digit_chains(rt: Retarget) -> dict[str, list[str]]:
    """Per human digit, the robot joints it drives (by each joint's first source)."""
    chains: dict[str, list[str]] = {}
    for k, name in enumerate(rt.joint_names):
        cols = np.nonzero(rt.gain[k])[0]
        if len(cols):
            curve = hand.CURVES[int(cols[0])]
            if curve.hand == "ri":
                chains.setdefault(curve.digit, []).append(name)
    return chains


class GraspModel:
    """The robot's and the human model's tips for one retarget table's joints."""

    def __init__(self, rt: Retarget, model_path: str | Path,
                 capture_deg: FloatArray | None = None) -> None:
        self.joint_names = rt.joint_names
        self.chains = digit_chains(rt)
        if "Thumb" not in self.chains:
            raise ConfigError("no robot joint follows the thumb: no pinch to fit",
                              file=str(model_path))
        self.low, self.high = rt.low_deg, rt.high_deg
        self.robot = RobotTips(model_path, rt.joint_names, self.chains)
        self.human = HumanTips(self.robot.digits)
        self.scale = self.robot.length_m / self.human.length_m
        self.fist = fist_pose()
        self.pinches: list[Pinch] = pinch_poses(HumanTips())
        self.capture = capture_deg
        self.flexion = {d: [rt.index(j) for j in js if self._is_flexion(rt, rt.index(j))]
                        for d, js in self.chains.items() if d != "Thumb"}

    @staticmethod
    def _is_flexion(rt: Retarget, k: int) -> bool:
        cols = np.nonzero(rt.gain[k])[0]
        return any(hand.CURVE_NAMES[int(c)].endswith(FLEXION_SUFFIXES) for c in cols)

    def human_tips(self, poses: FloatArray) -> FloatArray:
        """The human tips carried onto the robot (n, digits, 3), metres: each digit's
        tip relative to its base, scaled by the robot digit's length over the human's,
        from the robot digit's base."""
        h, r = self.human, self.robot
        scale = (r.digit_length_m / h.digit_length_m)[:, None]
        out: FloatArray = r.bases + scale * (h.tips(poses) - h.bases)
        return out

    def robot_tips(self, joints_deg: FloatArray) -> FloatArray:
        return self.robot.tips(joints_deg)

    def closure(self, joints_deg: FloatArray) -> dict[str, float]:
        """Per finger: share of its flexion range (0 -> upper limit) at these joints."""
        out = {}
        for d, rows in self.flexion.items():
            hi = np.maximum(self.high[rows], 1e-9)
            out[d.lower()] = float(np.clip(joints_deg[rows], 0.0, hi).sum() / hi.sum())
        return out

    def pinch_gaps_mm(self, rt: Retarget) -> list[float]:
        """The robot's thumb-finger tip gap at each human pinch, mm."""
        t = self.robot.digits.index("Thumb")
        out = []
        for p in self.pinches:
            tips = self.robot_tips(rt.apply_many(p.pose_deg[None]))[0]
            f = self.robot.digits.index(p.finger)
            out.append(float(1000.0 * np.linalg.norm(tips[t] - tips[f])))
        return out

    def grade(self, rt: Retarget) -> GraspReport:
        """The figures of :class:`GraspReport` for ``rt`` (same joints as this model's)."""
        closure = self.closure(rt.apply_many(self.fist[None])[0])
        gaps: dict[str, float] = {}
        for p, g in zip(self.pinches, self.pinch_gaps_mm(rt), strict=True):
            key = f"thumb_{p.finger.lower()}"
            gaps[key] = max(gaps.get(key, 0.0), g)
        err: dict[str, float] = {}
        if self.capture is not None:
            d = self.robot_tips(rt.apply_many(self.capture)) - self.human_tips(self.capture)
            e = 1000.0 * np.linalg.norm(d, axis=2)
            err = {"median": float(np.median(e)), "p95": float(np.percentile(e, 95))}
            for k, digit in enumerate(self.robot.digits):
                err[f"{digit.lower()}_median"] = float(np.median(e[:, k]))
        fingers = {d.lower(): list(js) for d, js in self.chains.items()}
        return GraspReport(closure, gaps, err, fingers, self.scale)


@dataclass(frozen=True)
class FitResult:
    """A fitted table, its figures before and after, and the solver's verdict."""

    retarget: Retarget
    before: GraspReport
    after: GraspReport
    iterations: int
    message: str


def _is_coupling(rt: Retarget, thumb: set[int], k: int, c: int) -> bool:
    """Whether (row ``k``, curve ``c``) is a coupling source: a thumb joint's from a finger."""
    return k in thumb and hand.CURVES[c].digit != "Thumb"


def _free_entries(rt: Retarget, thumb: set[int], couple: bool
                  ) -> tuple[list[tuple[int, int]], FloatArray, FloatArray, FloatArray]:
    """(row, column) gains the fit moves (each joint's own sources and the thumb rows'
    coupling sources), their bounds (an own source's sign kept; with ``couple`` a thumb
    row's own sources at least :data:`THUMB_GAIN_FLOOR`) and the gain each is pulled
    toward (its sign; 0 for a coupling source)."""
    entries: list[tuple[int, int]] = []
    lo: list[float] = []
    hi: list[float] = []
    prior: list[float] = []
    a, b = GAIN_BOUNDS
    for k in range(len(rt.joint_names)):
        for c in np.nonzero(rt.gain[k])[0]:
            g = rt.gain[k, c]
            entries.append((k, int(c)))
            if _is_coupling(rt, thumb, k, int(c)):
                lo.append(-COUPLING_BOUND)
                hi.append(COUPLING_BOUND)
                prior.append(0.0)
            else:
                floor = THUMB_GAIN_FLOOR if couple and k in thumb else a
                lo.append(floor if g > 0 else -b)
                hi.append(b if g > 0 else -floor)
                prior.append(float(np.sign(g)))
    return entries, np.array(lo), np.array(hi), np.array(prior)


def _flexes(rt: Retarget, k: int) -> bool:
    """Whether row ``k``'s sources are all flexion curves (a thumb joint that closes the
    thumb, not one that swings or turns its base)."""
    return all(hand.CURVES[int(c)].motion is hand.Motion.FLEXION
               for c in np.flatnonzero(rt.gain[k]))


def _with_coupling(rt: Retarget, thumb: set[int]) -> Retarget:
    """``rt`` with every thumb flexion row given the :data:`COUPLING_CURVES` as sources
    (a tiny gain marks a new one: the fit starts it from 0)."""
    gain = rt.gain.copy()
    for k in sorted(k for k in thumb if _flexes(rt, k)):
        for name in COUPLING_CURVES:
            c = hand.curve_index(name)
            if gain[k, c] == 0.0:
                gain[k, c] = 1e-9
    return dataclasses.replace(rt, gain=gain)


def fit_retarget(rt: Retarget, model_path: str | Path, capture_deg: FloatArray,
                 *, progress: Callable[[str], None] | None = None,
                 max_evaluations: int = 60, hold: Sequence[str] = (),
                 couple: bool = False) -> FitResult:
    """Fit ``rt``'s gains and offsets (see the module docstring); ranges are kept.

    ``hold``: robot joints kept as they are. With every thumb joint held the pinch
    terms are left out (they could only bend the fingers toward a thumb that does not
    follow). ``couple``: the free thumb joints may also read :data:`COUPLING_CURVES`
    (a table that has coupling sources is fitted so whether asked or not)."""
    for name in hold:
        rt.index(name)  # a KeyError naming the known joints
    held = {rt.index(name) for name in hold}
    gm = GraspModel(rt, model_path, capture_deg)
    thumb = {rt.index(j) for j in gm.chains["Thumb"]}
    given = rt
    couple = couple or any(_is_coupling(rt, thumb, k, int(c))
                           for k in thumb for c in np.flatnonzero(rt.gain[k]))
    if couple:
        rt = _with_coupling(rt, thumb - held)
    entries, g_lo, g_hi, prior_all = _free_entries(rt, thumb, couple)
    free = [i for i, (k, _) in enumerate(entries) if k not in held]
    entries = [entries[i] for i in free]
    g_lo, g_hi, prior = g_lo[free], g_hi[free], prior_all[free]
    thumb_held = thumb <= held
    rows = sorted({k for k, _ in entries})
    rr = np.array([k for k, _ in entries])
    cc = np.array([c for _, c in entries])
    lo = np.concatenate([g_lo, rt.low_deg[rows]])
    hi = np.concatenate([g_hi, rt.high_deg[rows]])
    x0 = np.clip(np.concatenate([rt.gain[rr, cc], rt.offset_deg[rows]]), lo, hi)
    cap = capture_deg[::CAPTURE_STEP]
    pinch = np.array([p.pose_deg for p in gm.pinches])
    poses = np.vstack([cap, gm.fist[None], pinch])
    human = gm.human_tips(poses)
    n_cap = len(cap)
    t = gm.robot.digits.index("Thumb")
    f_idx = [gm.robot.digits.index(p.finger) for p in gm.pinches]
    w = WEIGHTS
    digit_w = np.where(np.array(gm.robot.digits) == "Thumb", w["thumb"], 1.0)[None, :, None]

    def table(x: FloatArray) -> Retarget:
        gain = rt.gain.copy()
        gain[rr, cc] = x[:len(entries)]
        off = rt.offset_deg.copy()
        off[rows] = x[len(entries):]
        return dataclasses.replace(rt, gain=gain, offset_deg=off, table=None)

    def residual(x: FloatArray, pinch_w: float) -> FloatArray:
        tab = table(x)
        q = tab.apply_many(poses)
        raw = tab.unclipped_many(cap)[:, rows]
        past = np.maximum(rt.low_deg[rows] - raw, 0.0) + np.maximum(raw - rt.high_deg[rows], 0.0)
        tips = 1000.0 * gm.robot_tips(q)
        gaps = tips[n_cap + 1:, t] - tips[n_cap + 1:][np.arange(len(pinch)), f_idx]
        d = (tips - 1000.0 * human) * digit_w
        short = np.array([max(0.0, CLOSURE_GOAL - c) for c in gm.closure(q[n_cap]).values()])
        return np.concatenate([
            w["capture"] * d[:n_cap].ravel() / np.sqrt(n_cap),
            w["fist"] * d[n_cap].ravel(),
            pinch_w * gaps.ravel() / np.sqrt(len(pinch)),
            w["closure"] * short,
            w["gain"] * (x[:len(entries)] - prior),
            w["clip"] * past.ravel() / np.sqrt(n_cap),
        ])

    before = gm.grade(given)
    if progress:
        progress(f"fitting {len(x0)} gains and offsets over {len(poses)} poses")
    x, nfev, message = x0, 0, ""
    for stage in (1.0,) if thumb_held else PINCH_STAGES:
        pinch_w = 0.0 if thumb_held else stage * w["pinch"]
        sol = least_squares(residual, x, bounds=(lo, hi), diff_step=1e-3,
                            max_nfev=max_evaluations, kwargs={"pinch_w": pinch_w})
        x, nfev, message = sol.x, nfev + int(sol.nfev), str(sol.message)
    fitted = dataclasses.replace(_rounded(table(x)), table=given.table)
    keep = sorted(held)
    fitted.gain[keep] = given.gain[keep]  # held rows exactly as they were, not rounded
    fitted.offset_deg[keep] = given.offset_deg[keep]
    return FitResult(fitted, before, gm.grade(fitted), nfev, message)


def _rounded(rt: Retarget) -> Retarget:
    """Gains to 0.01 (a gain under 0.005 dropped), offsets to 0.1 deg, as a table writes."""
    gain = np.round(rt.gain, 2)
    gain[np.abs(gain) < 0.005] = 0.0
    return dataclasses.replace(rt, gain=gain, offset_deg=np.round(rt.offset_deg, 1))
