"""The full pose and its counters in compiled passes (``kernels.pose_from_curves``,
``kernels.account_pose``) against the same pose built in numpy from the map and the sag
grid's own lookups, for each way the left hand is made, a left-glove loop and a robot."""

from __future__ import annotations

import numpy as np
import pytest

from handrig.app.hands import build_session_parts
from handrig.app.parts import build_parts
from handrig.errors import DataError
from handrig.pose.pipeline import POSE_SIZE, PosePipeline


def reference_pose(p: PosePipeline, c: np.ndarray, inc: float, rot: float) -> np.ndarray:
    """The full pose as numpy builds it: the map's curves, then each hand's sag from
    the grid's lookup (minus its rest pose, times the gain)."""
    pose = np.zeros(POSE_SIZE)
    pose[:50] = p.expander.expand(c)
    if p.left_hand == "mirror":
        pose[25:50] = pose[0:25]
    grid = p._grids["ri"]
    live, other = ("le", "ri") if p.glove_hand == "le" else ("ri", "le")
    other_forearm = ((inc, rot) if p.left_hand == "mirror" and live == "ri"
                     else p.other_forearm_deg)
    for h, (i, r) in ((live, (inc, rot)), (other, other_forearm)):
        offsets = (grid.lookup(i, r) - grid.rest_deg) * p.sag_gain
        idx = p.sag_index[h]
        if h == "le" and live == "ri" and p.left_hand == "relaxed":
            pose[idx] = grid.rest_deg
        pose[idx] += offsets
    return pose


def near_a_limit(values: np.ndarray, low: np.ndarray, high: np.ndarray) -> bool:
    """Whether a value sits on a limit to rounding, not on it exactly (where the two
    sums may fall either side of it)."""
    near = ((np.abs(values - low) < 1e-9) & (values != low)) | (
        (np.abs(values - high) < 1e-9) & (values != high))
    return bool(np.any(near))


def check(p: PosePipeline, rng: np.random.Generator, n: int = 120) -> int:
    k = len(p.control_means_deg)
    checked = 0
    for _ in range(n):
        c = p.control_means_deg + rng.normal(0.0, 60.0, k)  # often past the limits
        inc, rot = float(rng.uniform(-90.0, 90.0)), float(rng.uniform(-400.0, 400.0))
        p.servo_targets(c, inc, rot, 0.005)
        want = reference_pose(p, c, inc, rot)
        np.testing.assert_allclose(p.full_pose(c, inc, rot), want, rtol=0.0, atol=1e-9)
        clamped = np.clip(want, p.pose_low, p.pose_high)
        robot = p.robot_path
        step = (want[p.servo_index] if robot is None
                else robot.full_gain @ clamped[:50] + robot.offset)
        over = (step < p.servo_low) | (step > p.servo_high)
        slewed = int(np.count_nonzero(np.abs(p.raw_targets - p.targets) > 1e-9))
        before = (p.clamps, p.servo_clamps, p.slewed, p.servo_clamps_by_servo.copy())
        got = p.account(c, inc, rot).copy()
        np.testing.assert_allclose(got, clamped, rtol=0.0, atol=1e-9)
        assert p.slewed - before[2] == slewed
        if near_a_limit(want, p.pose_low, p.pose_high) or near_a_limit(
                step, p.servo_low, p.servo_high):
            continue
        assert p.clamps - before[0] == int(np.count_nonzero(clamped != want))
        assert p.servo_clamps - before[1] == int(np.count_nonzero(over))
        np.testing.assert_array_equal(p.servo_clamps_by_servo - before[3], over)
        checked += 1
    return checked


@pytest.mark.parametrize("left_hand", ["map", "mirror", "relaxed"])
def test_the_compiled_pose_is_numpys_for_each_left_hand(left_hand: str) -> None:
    p = build_parts(None).pipeline
    p.left_hand = left_hand  # the pose's own branch; the servo path is not under test
    assert check(p, np.random.default_rng(7)) > 60


def test_a_robot_rig_counts_its_retargeted_joints() -> None:
    p = build_parts("leap").pipeline
    assert p.robot_path is not None
    assert check(p, np.random.default_rng(8)) > 60


def test_the_left_gloves_loop_puts_its_own_forearm_on_the_left_hand() -> None:
    session = build_session_parts("puppet_two_hands", glove_per_hand=True)
    p = session.hands[1].pipeline
    assert p.glove_hand == "le"
    assert check(p, np.random.default_rng(9)) > 60


def test_a_nan_forearm_is_refused_as_the_grid_refuses_it() -> None:
    p = build_parts(None).pipeline
    with pytest.raises(DataError, match="NaN"):
        p.account(p.control_means_deg, float("nan"), 0.0)
    with pytest.raises(DataError, match="NaN"):
        p.full_pose(p.control_means_deg, float("nan"), 0.0)
