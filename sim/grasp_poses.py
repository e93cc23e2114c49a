"""The human hand model's grasps: a fist and thumb-finger pinches, as 50 curves.

**Fist**: every finger's MCP, PIP and DIP flexion at its anatomical upper limit
(:func:`handrig.hand.anatomical_limits_deg`), MCP side-to-side at 0; the thumb folded
over the fingers (:data:`FIST_THUMB_DEG`, assumed: within its ranges, IP and MCP flexed
about two thirds, the metacarpal flexed and turned a little toward the fingers).

**Pinch**: the thumb tip on a finger's tip, found on the model
(:mod:`sim.hand_model` through :class:`sim.hand_kinematics.HumanTips`): for each finger
flexion level of :data:`PINCH_FINGER_DEG` (a tip pinch, a pad pinch and a rounder
one), the thumb's five curves and the finger's three flexions are solved (bounded least
squares within the anatomical ranges) for tip distance 0, held near the level's
finger flexion and a natural thumb (:data:`PINCH_THUMB_DEG`) by weak pulls (0.1 and
0.05 mm per degree). Other fingers rest lightly curled
(:data:`PINCH_OTHERS_DEG`). A pinch whose tips stay apart by more than
:data:`PINCH_TOUCH_MM` is an error: the model cannot make it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from handrig import hand
from handrig.errors import DataError
from sim.hand_kinematics import HumanTips

FloatArray = NDArray[np.float64]

FIST_THUMB_DEG: dict[str, float] = {
    "ThumbCMCx": 20.0, "ThumbCMCy": 10.0, "ThumbCMCz": 25.0, "ThumbMCPz": 40.0,
    "ThumbIPz": 55.0,
}
PINCH_FINGER_DEG: tuple[tuple[float, float, float], ...] = (
    (30.0, 35.0, 10.0), (40.0, 45.0, 25.0), (50.0, 60.0, 35.0),
)
"""Finger MCP, PIP, DIP flexion the pinch solve starts from and stays near (assumed)."""
PINCH_THUMB_DEG = np.array([15.0, 30.0, 20.0, 25.0, 25.0])
"""Thumb CMC twist, abduction, flexion, MCP and IP flexion a pinch stays near (assumed)."""
PINCH_OTHERS_DEG: tuple[float, float, float] = (20.0, 25.0, 10.0)
PINCH_TOUCH_MM = 1.0
PINCH_FINGERS: tuple[str, ...] = ("Index", "Middle")
THUMB_CURVES: tuple[str, ...] = tuple(
    f"riThumb{j}{a}" for j, a in hand.THUMB_JOINTS)


@dataclass(frozen=True)
class Pinch:
    """A pinch of the thumb and ``finger``: the pose (50 curves) and the model's tip gap."""

    finger: str
    pose_deg: FloatArray
    gap_mm: float


def fist_pose() -> FloatArray:
    """The human fist as the 50 curves (right hand; left hand zero)."""
    pose = np.zeros(len(hand.CURVE_NAMES))
    for f in hand.FINGERS:
        for j in ("MCPy", "PIPy", "DIPy"):
            name = f"ri{f}{j}"
            pose[hand.curve_index(name)] = hand.anatomical_limits_deg(name)[1]
    for name, v in FIST_THUMB_DEG.items():
        pose[hand.curve_index("ri" + name)] = v
    return pose


def _finger_curves(finger: str) -> list[int]:
    return [hand.curve_index(f"ri{finger}{j}") for j in ("MCPy", "PIPy", "DIPy")]


def pinch_poses(tips: HumanTips | None = None) -> list[Pinch]:
    """Thumb-index and thumb-middle pinches, one per level of :data:`PINCH_FINGER_DEG`."""
    tips = tips or HumanTips()
    t = tips.digits.index("Thumb")
    out = []
    for finger in PINCH_FINGERS:
        f = tips.digits.index(finger)
        cols = [hand.curve_index(n) for n in THUMB_CURVES] + _finger_curves(finger)
        bounds = np.array([hand.anatomical_limits_deg(hand.CURVE_NAMES[c]) for c in cols])
        for level in PINCH_FINGER_DEG:
            base = np.zeros(len(hand.CURVE_NAMES))
            for other in hand.FINGERS:
                if other != finger:
                    base[_finger_curves(other)] = PINCH_OTHERS_DEG
            want = np.asarray(level)

            def residual(x: FloatArray, base: FloatArray = base, want: FloatArray = want,
                         f: int = f, cols: list[int] = cols) -> FloatArray:
                pose = base.copy()
                pose[cols] = x
                p = tips.tips(pose)[0]
                gap_mm = 1000.0 * (p[t] - p[f])
                return np.concatenate([gap_mm, 0.1 * (x[5:] - want),
                                       0.05 * (x[:5] - PINCH_THUMB_DEG)])

            x0 = np.concatenate([PINCH_THUMB_DEG, want])
            x0 = np.clip(x0, bounds[:, 0], bounds[:, 1])
            sol = least_squares(residual, x0, bounds=(bounds[:, 0], bounds[:, 1]),
                                x_scale=10.0, diff_step=1e-4)
            pose = base.copy()
            pose[cols] = sol.x
            p = tips.tips(pose)[0]
            gap = float(1000.0 * np.linalg.norm(p[t] - p[f]))
            if gap > PINCH_TOUCH_MM:
                raise DataError(f"the hand model cannot pinch thumb and {finger.lower()} at "
                                f"finger flexion {level} deg: the tips stay {gap:.1f} mm apart")
            out.append(Pinch(finger, pose, gap))
    return out
