"""The retarget step run backwards: robot joint angles -> human curves that give them.

A robot hand's loop follows human curves (:mod:`handrig.pose.retarget`: ``robot =
clip(offset + G @ clamp(human))``, the curves clamped to the human joint limits
first). A program that commands the robot's own joints (a LeRobot action, a policy)
is turned into curves here, and the loop's own retarget turns them back, so the
servos see the same limits, slew limit and policies as from a glove.

Each curve is solved for by one robot joint row, its *owner*: rows are taken fewest
sources first (a finger's own joint before LEAP's thumb rows, which also read the
index and middle flexion), and a row owns the curves no earlier row took
(:func:`inverse_plan`). A row's target, less its offset and what the curves owned
by earlier rows give it, is met by its own curves ``h_i = clip(g_i * t, low_i,
high_i)`` with the one scalar ``t`` that makes the sum right: the sum is monotone in
``t``, so a bisection finds it. A one-curve row is the exact division. A target
outside what the clamped curves can reach gets the nearest reachable angle; a row
without sources is its offset (the loop holds it there). Curves no row reads are 0
(the flat hand): the robot does not see them. :func:`check_invertible` refuses a
table with a row that owns no curve (its target would be set by other joints').
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.errors import ConfigError

FloatArray = NDArray[np.float64]
BISECTIONS = 60
"""Halvings of the scalar's interval: far below a microdegree for any table's gains."""


def inverse_plan(gain: FloatArray) -> list[tuple[int, NDArray[np.intp], NDArray[np.intp]]]:
    """``(row, owned curves, curves owned by earlier rows)`` for each row with sources,
    in the order they are solved (module docstring)."""
    g = np.asarray(gain, dtype=np.float64)
    counts = np.count_nonzero(g, axis=1)
    owned = np.zeros(g.shape[1], dtype=bool)
    plan = []
    for row in sorted(np.flatnonzero(counts).tolist(), key=lambda r: (counts[r], r)):
        cols = np.flatnonzero(g[row])
        mine = cols[~owned[cols]]
        plan.append((int(row), mine, cols[owned[cols]]))
        owned[mine] = True
    return plan


def check_invertible(gain: FloatArray, joint_names: Sequence[str]) -> None:
    """ConfigError when a robot joint reads only curves other joints own: its target
    could then ask those curves for a second angle."""
    g = np.asarray(gain, dtype=np.float64)
    for row, mine, _ in inverse_plan(g):
        if mine.size == 0:
            c = int(np.flatnonzero(g[row])[0])
            rows = [joint_names[int(r)] for r in np.flatnonzero(g[:, c])]
            raise ConfigError("a human curve drives several robot joints: their targets "
                              "cannot be turned back into one pose",
                              key=f"joints.{rows[0]}.sources.{hand.CURVE_NAMES[c]}",
                              value=", ".join(rows),
                              allowed="each robot joint with a curve of its own")


def human_for_robot(robot_deg: FloatArray, gain: FloatArray, offset_deg: FloatArray,
                    human_low: FloatArray, human_high: FloatArray) -> FloatArray:
    """The 50 human curves (degrees, inside ``[human_low, human_high]``) whose retarget
    is ``robot_deg`` (J,) before the robot's own clip (module docstring). ``gain``
    (J, 50), ``offset_deg`` (J,), ``human_low``/``human_high`` (50,)."""
    g_all = np.asarray(gain, dtype=np.float64)
    target = np.asarray(robot_deg, dtype=np.float64) - np.asarray(offset_deg, dtype=np.float64)
    lo_all = np.asarray(human_low, dtype=np.float64)
    hi_all = np.asarray(human_high, dtype=np.float64)
    out = np.zeros(g_all.shape[1])
    for row, cols, fixed in inverse_plan(g_all):
        if cols.size == 0:
            continue
        want = target[row] - float(g_all[row, fixed] @ out[fixed])
        g, lo, hi = g_all[row, cols], lo_all[cols], hi_all[cols]
        if cols.size == 1:
            out[cols[0]] = np.clip(want / g[0], lo[0], hi[0])
            continue
        # g_i * clip(g_i t, ...) rises with t; past this span every curve sits at a limit
        span = float(np.max(np.maximum(np.abs(lo), np.abs(hi)) / np.abs(g))) + 1.0
        a, b = -span, span
        for _ in range(BISECTIONS):
            mid = 0.5 * (a + b)
            if float(g @ np.clip(g * mid, lo, hi)) < want:
                a = mid
            else:
                b = mid
        out[cols] = np.clip(g * 0.5 * (a + b), lo, hi)
    return out
