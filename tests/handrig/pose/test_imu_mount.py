"""The IMU's mounting from two held poses (handrig/imu_mount.py), alone and through
``handrig calibrate glove`` against an emulated glove whose IMU sits askew."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handrig.cli import calibrate_glove
from handrig.devices.glove_calibration import load_glove_config
from handrig.errors import DataError, HandrigError
from handrig.pose.imu_mount import (
    angle_between_deg,
    askew_mount,
    imu_quaternion,
    mount_from_poses,
    up_in_imu,
)
from handrig.pose.orientation import ForearmOrientation
from sim.calibration_motion import ScriptedSensors, timed_recording
from sim.glove_emulator import GloveEmulator

SETTLE_S, HOLD_S = 0.25, 0.35


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


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="handrig")
    calibrate_glove.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except HandrigError as exc:
        print(f"handrig: error: {exc}", file=sys.stderr)
        return 2


def test_calibrate_glove_finds_an_imu_mounted_askew(tmp_path: Path, capsys):  # type: ignore[no-untyped-def]
    true = askew_mount(30.0, 15.0)
    sensors = ScriptedSensors.from_config(load_glove_config())
    rec = timed_recording(sensors, pose_s=SETTLE_S + HOLD_S, transition_s=0.15, imu_mount=true)
    out = tmp_path / "glove.toml"
    with GloveEmulator(rec, "frames", rate_hz=200.0) as emu:
        status = main(["calibrate", "glove", "--glove", emu.port_path, "--yes", "--settle",
                       str(SETTLE_S), "--hold", str(HOLD_S), "--out", str(out)])
    text = capsys.readouterr().out
    assert status == 0, text
    assert "palm to vertical" in text and "IMU mount_xyzw" in text, text.splitlines()
    found = Rotation.from_quat(load_glove_config(out).imu.mount_xyzw)
    assert angle_between_deg(found, true) < 2.0, (found.as_quat(), true.as_quat())
