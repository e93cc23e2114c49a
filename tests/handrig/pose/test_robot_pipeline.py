"""A robot rig's servo path: the human curves, clamped, then the retarget table, in the one
compiled servo-target call; checked against the numpy steps it replaces."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from handrig.app import parts as app_parts
from handrig.errors import ConfigError
from handrig.pose import kernels
from handrig.pose.pipeline import PosePipeline
from handrig.pose.retarget import retarget
from handrig.pose.robot_rig import RobotRigConfig, robot_retarget


@pytest.fixture(scope="module")
def leap() -> app_parts.RigParts:
    return app_parts.build_parts("leap")


def _reference(pl: PosePipeline, controls: np.ndarray, incl: float, rot: float) -> np.ndarray:
    """The step in numpy: full pose, clamp to the joint limits, retarget, servo limits."""
    pose = pl.full_pose(controls, incl, rot).copy()
    np.clip(pose, pl.pose_low, pl.pose_high, out=pose)
    assert pl.retarget is not None
    rt = pl.retarget
    rows = [rt.joint_names.index(j) for j in pl.servo_joints]
    out = np.empty(len(rows))
    retarget(pose[:50], rt.gain[rows], rt.offset_deg[rows], pl.servo_low, pl.servo_high, out)
    return out


def _fresh(parts: app_parts.RigParts, **kw: object) -> PosePipeline:
    rig = parts.rig_config
    assert isinstance(rig, RobotRigConfig)
    args: dict[str, object] = dict(
        servo_limits_deg=np.array([[s.min_deg, s.max_deg] for s in rig.servos]),
        slew_deg_s=rig.loop.slew_deg_s, sag_gain=rig.effective_sag_gain,
        left_hand=rig.loop.left_hand, control_means_deg=parts.expander.control_means_deg,
        retarget=robot_retarget(rig))
    args.update(kw)
    return PosePipeline(parts.expander, parts.sag, [s.joint for s in rig.servos],
                        **args)  # type: ignore[arg-type]


def test_leap_pipeline_drives_the_robot_joints_in_bus_order(leap: app_parts.RigParts) -> None:
    pl = leap.pipeline
    assert pl.retarget is not None and pl.robot_path is not None
    assert pl.servo_joints == tuple(s.joint for s in leap.rig_config.servos)
    assert pl.servo_joints[:2] == ("if_rot", "if_mcp")  # bus order, not the table's
    assert pl.sag_gain == 0.0 and pl.servo_path.sag.cell_offsets_deg.shape[0] == 0
    # only the curves some row reads are computed
    assert len(pl.robot_path.curves) < 50


def test_first_step_matches_the_numpy_reference(leap: app_parts.RigParts) -> None:
    rng = np.random.default_rng(3)
    for _ in range(50):
        pl = _fresh(leap)
        c = leap.expander.control_means_deg + rng.normal(0.0, 40.0, len(leap.expander.controls))
        incl, rot = float(rng.uniform(-90, 90)), float(rng.uniform(-180, 180))
        got = pl.servo_targets(c, incl, rot, 0.005).copy()
        np.testing.assert_allclose(got, _reference(pl, c, incl, rot), atol=1e-9)
        assert np.all(got >= pl.servo_low) and np.all(got <= pl.servo_high)


def test_sag_can_be_switched_on(leap: app_parts.RigParts) -> None:
    rig = leap.rig_config
    assert isinstance(rig, RobotRigConfig) and rig.robot is not None
    on = dataclasses.replace(rig, robot=dataclasses.replace(rig.robot, sag=True))
    assert on.effective_sag_gain == rig.loop.sag_gain > 0.0
    with_sag = _fresh(leap, sag_gain=on.effective_sag_gain)
    without = _fresh(leap)
    c = leap.expander.control_means_deg.copy()
    a = with_sag.servo_targets(c, 0.0, 90.0, 0.005).copy()
    b = without.servo_targets(c, 0.0, 90.0, 0.005).copy()
    np.testing.assert_allclose(a, _reference(with_sag, c, 0.0, 90.0), atol=1e-9)
    assert not np.allclose(a, b)  # the forearm level, palm sideways: the fingers sag


def test_slew_limit_and_held_non_finite_target(leap: app_parts.RigParts) -> None:
    pl = _fresh(leap)
    c = leap.expander.control_means_deg.copy()
    first = pl.servo_targets(c, -90.0, 0.0, 0.005).copy()
    c2 = c + 60.0
    second = pl.servo_targets(c2, -90.0, 0.0, 0.005).copy()
    assert np.max(np.abs(second - first)) <= pl.slew_deg_s * 0.005 + 1e-9
    index = list(leap.expander.controls).index("riIndexMCPy")
    bad = c.copy()
    bad[index] = np.nan
    before = pl.rejected
    third = pl.servo_targets(bad, -90.0, 0.0, 0.005).copy()
    # a non-finite control makes every curve the map computes from it non-finite, as in
    # the human rig's kernel: every servo holds its target
    np.testing.assert_array_equal(third, second)
    assert pl.rejected == before + len(pl.servo_joints)


def test_kernel_holds_the_previous_target_without_nan_leaking() -> None:
    f = np.zeros(2)
    a = np.eye(2)
    human, raw, targets = np.zeros(2), np.zeros(3), np.array([1.0, 2.0, 3.0])
    # rows [1, 0], [0, 1], [0.5, 0.5] by their nonzero entries
    start, curve = np.array([0, 1, 2, 4]), np.array([0, 1, 0, 1])
    gain = np.array([1.0, 1.0, 0.5, 0.5])
    held = kernels.robot_servo_targets(
        np.array([0.0, 4.0]), np.zeros(0), np.zeros(2), a, np.array([np.inf, 0.0]), np.zeros(2),
        np.zeros(2), 0.0,
        np.zeros((0, 1, 4, 1)),
        np.zeros(2, np.int64), 0.0, f - np.inf, f + np.inf, 0.0, 0.0, f - 100.0, f + 100.0,
        human, start, curve, gain,
        np.array([0.0, 1.0, 0.0]), np.full(3, -50.0), np.full(3, 50.0), targets, 100.0,
        False, raw)
    assert held == 2  # rows 0 and 2 read the bad curve; row 1 does not
    np.testing.assert_array_equal(targets, [1.0, 5.0, 3.0])


def test_relaxed_targets_and_account_use_the_retarget(leap: app_parts.RigParts) -> None:
    pl = _fresh(leap)
    relaxed = pl.relaxed_targets(-90.0, 0.0).copy()
    pose = np.clip(pl.relaxed, pl.pose_low, pl.pose_high)
    rt = pl.retarget
    assert rt is not None
    want = np.array([rt.apply(pose[:50])[rt.joint_names.index(j)] for j in pl.servo_joints])
    np.testing.assert_allclose(relaxed, np.clip(want, pl.servo_low, pl.servo_high), atol=1e-9)
    c = leap.expander.control_means_deg + 200.0  # far past every limit
    pl.servo_targets(c, -90.0, 0.0, 0.005)
    full = pl.account(c, -90.0, 0.0)
    assert full.shape == (54,)  # outputs still get the human pose
    rows = [rt.joint_names.index(j) for j in pl.servo_joints]
    unclipped = rt.unclipped_many(full[None, :50])[0, rows]
    outside = (unclipped < pl.servo_low) | (unclipped > pl.servo_high)
    assert pl.servo_clamps == int(np.count_nonzero(outside)) > 0


def test_a_servo_joint_without_a_table_row_is_refused(leap: app_parts.RigParts) -> None:
    rig = leap.rig_config
    assert isinstance(rig, RobotRigConfig)
    with pytest.raises(ConfigError, match="no row for servo joint 'nope'"):
        PosePipeline(leap.expander, None, ["if_mcp", "nope"], retarget=robot_retarget(rig))


def test_the_human_rig_builds_as_before() -> None:
    parts = app_parts.build_parts()
    assert parts.pipeline.retarget is None and parts.pipeline.robot_path is None
    assert parts.pipeline.sag_gain == parts.rig_config.loop.sag_gain
