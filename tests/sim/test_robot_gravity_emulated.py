"""Gravity on the emulated LEAP hand at Goal Current 350: its fingers stop short of their
goals under their own weight, and the rig's gravity compensation brings them there.
Simulated time (the MuJoCo model stepped directly): no realtime loop, no machine load."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from handrig.app.robot_gravity import build_gravity
from handrig.pose.robot_rig import RobotRigConfig, load_rig
from sim.robot_gravity_check import gravity_error, poses_deg

pytest.importorskip("mujoco")
GOAL_CURRENT_MA = 350  # the LEAP hand API's


def _leap(direction: tuple[float, float, float]) -> RobotRigConfig:
    rig = load_rig("leap")
    assert isinstance(rig, RobotRigConfig) and rig.robot is not None
    return dataclasses.replace(rig, robot=dataclasses.replace(
        rig.robot, gravity=True, gravity_direction=direction))


@pytest.mark.parametrize("direction", [(0.0, 0.0, -1.0), (0.0, 1.0, 0.0)])
def test_compensated_goals_hold_the_fingers_where_they_were_sent(
        direction: tuple[float, float, float]) -> None:
    """As drawn the flexion joints sag (index MCP ~1.1 deg), turned on its side the
    side-to-side joints (~0.6 deg); compensated, every joint rests within a tick or so."""
    rig = _leap(direction)
    low = np.array([s.min_deg for s in rig.servos])
    high = np.array([s.max_deg for s in rig.servos])
    comp = build_gravity(rig, low, high)
    assert comp is not None
    off = gravity_error(rig, None, goal_current_ma=GOAL_CURRENT_MA, settle_s=0.8)
    on = gravity_error(rig, comp, goal_current_ma=GOAL_CURRENT_MA, settle_s=0.8)
    assert off.max_deg > 0.5, off.per_joint_deg  # the emulated hand does sag
    assert on.max_deg < 0.1, on.per_joint_deg
    assert on.rms_deg < off.rms_deg / 5
    sagging = off.per_joint_deg > 0.3
    assert sagging.sum() >= 3  # several joints, not one
    assert np.all(on.per_joint_deg[sagging] < 0.1)


def test_the_emulator_in_free_fall_holds_the_test_poses() -> None:
    """What the test above measures is gravity's: without it the same poses, goals as
    sent, settle within a tick (no contact between fingers, no other error)."""
    rig = _leap((0.0, 0.0, -1.0))
    assert poses_deg(rig).shape == (3, 16)
    free = gravity_error(rig, None, goal_current_ma=GOAL_CURRENT_MA, settle_s=0.8,
                         emulator_gravity=False)
    assert free.max_deg < 0.06, free.per_joint_deg
