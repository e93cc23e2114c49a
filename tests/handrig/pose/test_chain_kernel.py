"""The compiled chain kernel: its matrix-to-quaternion step on every branch, and a
two-body chain worked by hand."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from handrig.pose.chain_kernel import _mat_to_quat, chain_poses


def test_matrix_to_quaternion_matches_scipy_on_every_branch() -> None:
    rots = Rotation.random(500, random_state=1)
    # near-half-turns about each axis take the three pivots other than w
    flips = Rotation.from_rotvec(np.array([[3.1, 0, 0], [0, 3.1, 0], [0, 0, 3.1],
                                           [math.pi, 0, 0], [0, 0, math.pi]]))
    q = np.empty(4)
    for r in [*rots, *flips]:
        _mat_to_quat(r.as_matrix(), q)
        expected = r.as_quat()
        expected *= np.sign(expected[3]) if expected[3] != 0 else 1.0
        assert q[3] >= 0.0
        assert np.allclose(q, expected, atol=1e-12) or np.allclose(q, -expected, atol=1e-12)


def test_two_hinged_bodies() -> None:
    """A root, then a body 1 m along x turned 90 deg about z: its point 1 m along its own x
    lands at (1, 1, 0); the frame is the body's (quaternion of 90 deg about z)."""
    out = np.zeros((2, 7))
    chain_poses(np.array([0.0, math.pi / 2]), np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]),
                np.array([-1, 0], np.intp), np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]),
                np.array([[0, -1, -1], [1, -1, -1]], np.intp), np.eye(3), np.zeros(3),
                np.array([0, 1], np.intp), np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]),
                np.eye(3), np.zeros((2, 3, 3)), np.zeros((2, 3)), np.zeros((3, 3)),
                np.zeros((3, 3)), out)
    assert np.allclose(out[0], [0, 0, 0, 0, 0, 0, 1])
    s = math.sqrt(0.5)
    assert np.allclose(out[1], [1, 1, 0, 0, 0, s, s])


def test_non_finite_angles_give_nan_joints_not_an_exception() -> None:
    from handrig.pose.openxr_hand import FINGER_FIRST, hand_joints

    pose = np.zeros(25)
    pose[5 + 1] = np.nan  # the index finger's MCP flexion
    pose[10 + 3] = np.inf  # the middle finger's PIP
    j = hand_joints(pose).poses
    assert np.isnan(j[FINGER_FIRST[0] + 2:FINGER_FIRST[0] + 5]).any(axis=1).all()
    assert np.isnan(j[FINGER_FIRST[1] + 3:FINGER_FIRST[1] + 5]).any(axis=1).all()
    assert np.isfinite(j[FINGER_FIRST[2]:]).all() and np.isfinite(j[:FINGER_FIRST[0]]).all()
