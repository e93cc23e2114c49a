"""The IMU's mounting from two held poses (handrig/imu_mount.py); through ``handrig
calibrate glove`` against an emulated glove: tests/handrig/cli/test_calibrate_glove_imu.py."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handrig.errors import DataError
from handrig.pose.imu_mount import (
    angle_between_deg,
    askew_mount,
    imu_quaternion,
    mount_from_poses,
    up_in_imu,
)
from handrig.pose.orientation import ForearmOrientation


def held(forearm_roll_deg: float, mount: Rotation, rng: np.random.Generator) -> np.ndarray:
    """A hold of 100 samples: any heading, a little tremor."""
    heading = rng.uniform(-180, 180)
    tremor = rng.normal(0.0, 0.5, (100, 3))
    forearm = (Rotation.from_euler("ZX", [heading, forearm_roll_deg], degrees=True)
               * Rotation.from_euler("xyz", tremor, degrees=True))
    return imu_quaternion(forearm, mount)


def test_two_poses_recover_an_askew_mount_and_the_angles_come_out_right():
    rng = np.random.default_rng(3)
    true = askew_mount(30.0, 15.0)
    found = mount_from_poses(up_in_imu(held(0.0, true, rng)), up_in_imu(held(90.0, true, rng)))
    assert angle_between_deg(found, true) < 0.5
    fo = ForearmOrientation(found)
    q = imu_quaternion(Rotation.from_euler("ZYX", [70.0, -25.0, 40.0], degrees=True), true)
    incl, rot = fo.angles(q)  # forearm 25 deg up (its y pitch is negative up), rolled 40
    assert abs(incl - 25.0) < 0.5 and abs(rot - 40.0) < 0.5


def test_poses_not_a_quarter_turn_apart_are_refused():
    rng = np.random.default_rng(4)
    m = askew_mount(0.0, 0.0)
    with pytest.raises(DataError, match="not about 90"):
        mount_from_poses(up_in_imu(held(0.0, m, rng)), up_in_imu(held(10.0, m, rng)))
