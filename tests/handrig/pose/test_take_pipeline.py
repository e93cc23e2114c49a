"""A performance as the loop's pose source: each servo gets its joint's recorded value,
clamped to the joint and servo limits and slew-limited; the relaxed pose is the live
rig's; the output pose is the take's own (clamped)."""

from __future__ import annotations

import numpy as np

from handrig.app.parts import build_parts
from handrig.app.takes import PlayTake, play_parts
from handrig.devices.glove_recording import GloveRecording
from handrig.pose.pipeline import POSE_NAMES, POSE_SIZE


def take_parts(rig: str | None = None):  # a performance's parts on the shipped rig
    parts = build_parts(rig)
    rec = GloveRecording(np.array([0.0]), np.zeros((1, POSE_SIZE)), np.zeros(1, np.int64),
                         POSE_NAMES)
    take = PlayTake(parts.rig_file, "performance", rec, 1, 0.0, 0.0, 1.0)
    return parts, play_parts(parts, take)


def test_each_servo_gets_its_joint_from_the_take_clamped_and_slew_limited() -> None:
    live, parts = take_parts()
    p = parts.pipeline
    rng = np.random.default_rng(3)
    pose = rng.uniform(-120.0, 120.0, POSE_SIZE)  # well past most limits
    idx = [POSE_NAMES.index(j) for j in p.servo_joints]
    assert any(i >= 50 for i in idx)  # the shipped rig drives the wrist too
    p.seed(np.clip(pose[idx], p.servo_low, p.servo_high))
    targets = p.servo_targets(parts.controls(pose, 0.0, np.zeros(POSE_SIZE)),
                              *parts.orientation(None), 0.01)
    expected = np.clip(pose[idx], p.servo_low, p.servo_high)
    np.testing.assert_allclose(targets, expected)  # no sag added: the take holds its own
    assert np.all(targets >= p.servo_low) and np.all(targets <= p.servo_high)
    np.testing.assert_allclose(p.servo_low, live.pipeline.servo_low)  # the live limits
    np.testing.assert_allclose(p.servo_high, live.pipeline.servo_high)
    far = pose.copy()
    far[idx] += 90.0
    step = p.servo_targets(far, *parts.orientation(None), 0.01)
    assert np.all(np.abs(step - targets) <= p.slew_deg_s * 0.01 + 1e-9)
    out = p.account(far, *parts.orientation(None))
    np.testing.assert_allclose(out, np.clip(far, p.pose_low, p.pose_high))


def test_the_relaxed_pose_is_the_live_rigs() -> None:
    live, parts = take_parts()
    forearm = parts.orientation(None)
    np.testing.assert_allclose(parts.pipeline.relaxed_targets(*forearm),
                               live.pipeline.relaxed_targets(*forearm), atol=1e-9)


def test_a_robot_rig_retargets_the_takes_curves() -> None:
    live, parts = take_parts("leap")
    p = parts.pipeline
    pose = np.zeros(POSE_SIZE)
    pose[:50] = live.pipeline.expander.expand(live.pipeline.control_means_deg)
    targets = p.servo_targets(pose, *parts.orientation(None), 10.0)
    robot = p.robot_path
    assert robot is not None
    expected = np.clip(robot.full_gain @ np.clip(pose[:50], p.pose_low[:50], p.pose_high[:50])
                       + robot.offset, p.servo_low, p.servo_high)
    np.testing.assert_allclose(targets, expected, atol=1e-9)
