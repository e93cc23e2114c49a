"""The retarget run backwards (handrig/pose/retarget_inverse.py): robot joint targets ->
the human curves whose retarget, through the loop's own clamp, gives them again."""

from __future__ import annotations

import numpy as np
import pytest

from handrig import hand
from handrig.config.loading import load_joint_limits
from handrig.errors import ConfigError
from handrig.pose.retarget_inverse import check_invertible, human_for_robot, inverse_plan
from handrig.pose.robot_rig import find_rig, robot_retarget

LIMITS = load_joint_limits()
LOW = np.array([LIMITS.of(n)[0] for n in hand.CURVE_NAMES])
HIGH = np.array([LIMITS.of(n)[1] for n in hand.CURVE_NAMES])


def forward(rt, human):
    """The loop's step: the curves clamped to the human limits, then the table."""
    return rt.offset_deg + rt.gain @ np.clip(human, LOW, HIGH)


@pytest.mark.parametrize("preset", ["leap", "orca"])
def test_targets_from_a_pose_come_back_exactly(preset: str) -> None:
    rt = robot_retarget(find_rig(preset)[1])
    check_invertible(rt.gain, rt.joint_names)
    rng = np.random.default_rng(7)
    read = np.any(rt.gain != 0.0, axis=1)
    for _ in range(200):
        human = rng.uniform(LOW, HIGH)
        robot = forward(rt, human)
        back = human_for_robot(robot, rt.gain, rt.offset_deg, LOW, HIGH)
        assert np.all(back >= LOW) and np.all(back <= HIGH)
        np.testing.assert_allclose(forward(rt, back)[read], robot[read], atol=1e-6)
    # a row of several curves (LEAP's thumb MCP) is solved, not split naively: ask for
    # the row's extreme over the curves it owns (the others are set by the joints that
    # own them), where one curve alone would have to leave its limits
    zero = np.zeros(len(LOW))
    for r, mine, fixed in inverse_plan(rt.gain):
        if mine.size < 2:
            continue
        g = rt.gain[r]
        top = rt.offset_deg[r] + float(g[fixed] @ zero[fixed]) + float(
            np.sum(np.where(g[mine] > 0, g[mine] * HIGH[mine], g[mine] * LOW[mine])))
        robot = forward(rt, zero)
        robot[r] = top - 1e-3
        back = human_for_robot(robot, rt.gain, rt.offset_deg, LOW, HIGH)
        assert forward(rt, back)[r] == pytest.approx(top - 1e-3, abs=1e-6)
        np.testing.assert_allclose(back[fixed], zero[fixed], atol=1e-9)  # others kept


def test_unreachable_targets_get_the_nearest_and_shared_curves_are_refused() -> None:
    rt = robot_retarget(find_rig("leap")[1])
    r = rt.index("if_mcp")
    robot = forward(rt, np.zeros(len(LOW)))
    robot[r] = 1e4  # beyond what the clamped curve can give
    back = human_for_robot(robot, rt.gain, rt.offset_deg, LOW, HIGH)
    g = rt.gain[r]
    assert forward(rt, back)[r] == pytest.approx(
        rt.offset_deg[r] + float(np.sum(np.where(g > 0, g * HIGH, g * LOW))))
    shared = rt.gain.copy()
    shared[rt.index("if_pip")] = shared[r]
    with pytest.raises(ConfigError, match="several robot joints") as err:
        check_invertible(shared, rt.joint_names)
    assert "riIndexMCPy" in str(err.value) and "if_mcp" in str(err.value)
