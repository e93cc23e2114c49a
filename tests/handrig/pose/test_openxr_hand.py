"""The 26 OpenXR hand joints: order and names, metres, a fist and a flat hand, mirroring.

Expected distances come from REFERENCE.md section 4's bone fractions of the hand length
(written out here), not from the code under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handrig import hand
from handrig.errors import DataError
from handrig.pose.openxr_hand import (
    JOINT_NAMES,
    TIPS,
    XR_JOINT_NAMES,
    OpenXrHand,
    XrPose,
    both_hands,
    hand_joints,
)

HL = 0.19
# REFERENCE.md section 4: metacarpal, proximal, middle, distal as fractions of HL
BONES = {"Index": (0.374, 0.245, 0.143, 0.097), "Middle": (0.373, 0.266, 0.170, 0.108),
         "Ring": (0.336, 0.244, 0.165, 0.107), "Pinky": (0.295, 0.204, 0.117, 0.093)}
THUMB = (0.251, 0.196, 0.158)
XR = {"Index": "INDEX", "Middle": "MIDDLE", "Ring": "RING", "Pinky": "LITTLE"}


def _pose(**values: float) -> np.ndarray:
    """A right hand's 25 curves, from ``riIndexMCPy=90``-style keywords ("ri" left off)."""
    p = np.zeros(hand.CURVES_PER_HAND)
    for name, v in values.items():
        p[hand.curve_index("ri" + name)] = v
    return p


def _fist() -> np.ndarray:
    return _pose(**{f"{d}{j}": 90.0 for d in BONES for j in ("MCPy", "PIPy", "DIPy")})


def _at(joints: np.ndarray, name: str) -> np.ndarray:
    return joints[JOINT_NAMES.index(name), :3]


def test_joint_order_and_names_are_openxrs() -> None:
    # XrHandJointEXT: PALM 0, WRIST 1, thumb 2-5, then index, middle, ring, little
    assert len(JOINT_NAMES) == 26
    assert XR_JOINT_NAMES[0] == "XR_HAND_JOINT_PALM_EXT"
    assert XR_JOINT_NAMES[1] == "XR_HAND_JOINT_WRIST_EXT"
    assert XR_JOINT_NAMES[2:6] == tuple(
        f"XR_HAND_JOINT_THUMB_{b}_EXT" for b in ("METACARPAL", "PROXIMAL", "DISTAL", "TIP"))
    for k, digit in enumerate(("INDEX", "MIDDLE", "RING", "LITTLE")):
        assert XR_JOINT_NAMES[6 + 5 * k:11 + 5 * k] == tuple(
            f"XR_HAND_JOINT_{digit}_{b}_EXT"
            for b in ("METACARPAL", "PROXIMAL", "INTERMEDIATE", "DISTAL", "TIP"))
    assert XR_JOINT_NAMES[25] == "XR_HAND_JOINT_LITTLE_TIP_EXT"
    assert TIPS == (5, 10, 15, 20, 25)
    joints = hand_joints(np.zeros(25))
    assert joints.poses.shape == (26, 7) and joints.radii_m.shape == (26,)
    assert np.array_equal(joints.joint("XR_HAND_JOINT_INDEX_TIP_EXT"), joints.poses[10])
    with pytest.raises(DataError, match="INDEX_TIP"):
        joints.joint("INDEX_FINGERTIP")


def test_flat_hand_in_metres_and_openxr_axes() -> None:
    j = hand_joints(np.zeros(25)).poses
    wrist = _at(j, "WRIST")
    # wrist to the middle fingertip is the hand length, straight ahead (-Z)
    assert np.allclose(_at(j, "MIDDLE_TIP") - wrist, [0.0, 0.0, -HL], atol=1e-9)
    for digit, (meta, prox, mid, dist) in BONES.items():
        base = _at(j, f"{XR[digit]}_PROXIMAL")
        tip = _at(j, f"{XR[digit]}_TIP")
        assert np.linalg.norm(tip - base) == pytest.approx((prox + mid + dist) * HL, abs=1e-9)
        assert np.linalg.norm(base - _at(j, f"{XR[digit]}_METACARPAL")) == pytest.approx(
            meta * HL, abs=1e-9)
    # the palm joint: the middle of the middle metacarpal
    mid_meta = (_at(j, "MIDDLE_METACARPAL") + _at(j, "MIDDLE_PROXIMAL")) / 2
    assert np.allclose(_at(j, "PALM"), mid_meta)
    # a right hand, palm down, pointing -Z: the thumb on -X, the little finger on +X
    assert _at(j, "THUMB_TIP")[0] < 0 < _at(j, "LITTLE_TIP")[0]
    # straight hand: every joint oriented as the forearm (-Z distal, +Y dorsal)
    assert np.allclose(np.abs(j[:, 6]), 1.0)
    radii = hand_joints(np.zeros(25)).radii_m
    assert np.all((radii > 0.003) & (radii < 0.02))


def test_fist_and_flat_hand_tip_distances() -> None:
    flat = hand_joints(np.zeros(25)).poses
    fist = hand_joints(_fist()).poses
    for digit, (_, prox, mid, dist) in BONES.items():
        # MCP, PIP and DIP at 90 deg: the proximal bone goes palmar, the middle one back
        # toward the wrist, the distal one dorsal again, in one plane:
        # tip - MCP = (back mid, palmar (prox - dist))
        expected = math.hypot(mid, prox - dist) * HL
        mcp = _at(fist, f"{XR[digit]}_PROXIMAL")
        tip = _at(fist, f"{XR[digit]}_TIP")
        assert np.linalg.norm(tip - mcp) == pytest.approx(expected, abs=1e-9)
        assert tip[1] - mcp[1] == pytest.approx(-(prox - dist) * HL, abs=1e-9)  # palmar
        assert tip[2] - mcp[2] == pytest.approx(mid * HL, abs=1e-9)  # back toward the wrist
        # the flat hand's tip is its digit's whole length from the MCP
        flat_tip = _at(flat, f"{XR[digit]}_TIP") - _at(flat, f"{XR[digit]}_PROXIMAL")
        assert np.linalg.norm(flat_tip) == pytest.approx((prox + mid + dist) * HL, abs=1e-9)
    # the middle fingertip to the palm joint: 0.7305 HL flat, about 0.16 HL in a fist
    palm_flat = np.linalg.norm(_at(flat, "MIDDLE_TIP") - _at(flat, "PALM"))
    palm_fist = np.linalg.norm(_at(fist, "MIDDLE_TIP") - _at(fist, "PALM"))
    meta, prox, mid, dist = BONES["Middle"]
    assert palm_flat == pytest.approx((meta / 2 + prox + mid + dist) * HL, abs=1e-9)
    assert palm_fist == pytest.approx(math.hypot(meta / 2 - mid, prox - dist) * HL, abs=1e-9)
    assert palm_fist < 0.04 < 0.12 < palm_flat


def test_joint_frames_follow_their_bones() -> None:
    """-Z of every finger joint runs along its bone toward the tip; Y is dorsal."""
    rng = np.random.default_rng(3)
    lim = hand.curve_limits_deg()[:25]
    for _ in range(20):
        j = hand_joints(rng.uniform(lim[:, 0], lim[:, 1]), wrist_deg=rng.uniform(-30, 30, 2))
        q = j.orientations_xyzw
        assert np.allclose(np.linalg.norm(q, axis=1), 1.0)
        rot = Rotation.from_quat(q).as_matrix()
        for first in (2, 6, 11, 16, 21):
            last = 5 if first == 2 else first + 4
            for k in range(first, last):
                bone = j.positions_m[k + 1] - j.positions_m[k]
                minus_z = -rot[k][:, 2]
                assert np.allclose(bone / np.linalg.norm(bone), minus_z, atol=1e-9)


def test_flexion_curls_palmar_and_abduction_goes_radial() -> None:
    flat = hand_joints(np.zeros(25)).poses
    bent = hand_joints(_pose(IndexMCPy=40.0)).poses
    assert _at(bent, "INDEX_TIP")[1] < _at(flat, "INDEX_TIP")[1] - 0.03  # down, palmar
    spread = hand_joints(_pose(IndexMCPx=15.0)).poses
    assert _at(spread, "INDEX_TIP")[0] < _at(flat, "INDEX_TIP")[0] - 0.02  # toward the thumb
    wrist_flexed = hand_joints(np.zeros(25), wrist_deg=(30.0, 0.0)).poses
    assert _at(wrist_flexed, "MIDDLE_TIP")[1] == pytest.approx(-HL * math.sin(math.radians(30)))


def test_left_hand_is_the_right_hands_mirror_image() -> None:
    rng = np.random.default_rng(7)
    lim = hand.curve_limits_deg()[:25]
    flip = np.diag([-1.0, 1.0, 1.0])
    for _ in range(10):
        pose = rng.uniform(lim[:, 0], lim[:, 1])
        wrist = rng.uniform(-30, 30, 2)
        right = hand_joints(pose, "ri", wrist_deg=wrist)
        left = hand_joints(pose, "le", wrist_deg=wrist)
        assert np.allclose(left.positions_m, right.positions_m @ flip, atol=1e-12)
        # mirrored frames: Y and Z reflected, X = Y x Z (so X flips too, then reflects)
        r = Rotation.from_quat(right.orientations_xyzw).as_matrix()
        lm = Rotation.from_quat(left.orientations_xyzw).as_matrix()
        assert np.allclose(lm, flip @ r @ flip, atol=1e-9)


def test_forearm_pose_moves_and_turns_the_whole_hand() -> None:
    pose = _fist()
    turn = Rotation.from_euler("y", 90, degrees=True)  # forearm now points -X
    at = XrPose((0.2, 1.0, -0.3), tuple(turn.as_quat()))
    home = hand_joints(pose).poses
    moved = hand_joints(pose, forearm=at).poses
    assert np.allclose(moved[:, :3], turn.apply(home[:, :3]) + np.array([0.2, 1.0, -0.3]))
    assert np.allclose(_at(hand_joints(np.zeros(25), forearm=at).poses, "MIDDLE_TIP"),
                       [0.2 - HL, 1.0, -0.3])
    with pytest.raises(DataError, match="unit quaternion"):
        XrPose((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 2.0))


def test_bad_input_is_a_clear_error() -> None:
    with pytest.raises(DataError, match="25 curves"):
        hand_joints(np.zeros(50))
    with pytest.raises(DataError, match="2 angles"):
        hand_joints(np.zeros(25), wrist_deg=(0.0,))
    with pytest.raises(DataError, match="hand length"):
        OpenXrHand("ri", 0.9)
    with pytest.raises(DataError, match="54 values"):
        both_hands(np.zeros(50))


def test_both_hands_from_a_full_pose_take_each_hands_curves_and_wrist() -> None:
    full = np.zeros(54)
    full[hand.curve_index("leIndexMCPy")] = 60.0
    full[hand.ALL_JOINT_NAMES.index("riWristFlexion")] = 20.0
    hands = both_hands(full)
    assert np.allclose(hands["le"].poses, hand_joints(_pose(IndexMCPy=60.0), "le").poses)
    assert np.allclose(hands["ri"].poses,
                       hand_joints(np.zeros(25), "ri", wrist_deg=(20.0, 0.0)).poses)


def test_thumb_lengths_are_the_models() -> None:
    j = hand_joints(np.zeros(25)).poses
    for a, b, frac in (("METACARPAL", "PROXIMAL", THUMB[0]), ("PROXIMAL", "DISTAL", THUMB[1]),
                       ("DISTAL", "TIP", THUMB[2])):
        d = np.linalg.norm(_at(j, f"THUMB_{b}") - _at(j, f"THUMB_{a}"))
        assert d == pytest.approx(frac * HL, abs=1e-9)
