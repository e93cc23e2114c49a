"""The OpenXR hand joints (handrig/pose/openxr_hand.py) agree with MuJoCo's forward
kinematics of the simulated hand (sim/hand_model.py): one set of bones, one set of axes."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handrig import hand
from handrig.hand import Hand
from handrig.pose.hand_geometry import hand_geometry
from handrig.pose.openxr_hand import FINGER_FIRST, MODEL_TO_XR, THUMB_FIRST, hand_joints
from sim.hand_model import dof_qpos_indices, hand_model_xml

FINGER_TWIST = [hand.curve_index(f"ri{d}MCPz") for d in hand.FINGERS]


@pytest.mark.parametrize("side", ["ri", "le"])
@pytest.mark.parametrize("hand_length_m", [0.19, 0.16])
def test_joints_match_mujoco(side: Hand, hand_length_m: float) -> None:
    model = mujoco.MjModel.from_xml_string(hand_model_xml(side, hand_length_m))
    data = mujoco.MjData(model)
    qidx = dof_qpos_indices(model, side)
    curve_of = hand.dof_curve_indices(side) - (0 if side == "ri" else 25)
    geo = hand_geometry(hand_length_m)
    rng = np.random.default_rng(11)
    lim = hand.curve_limits_deg()[:25]

    def body(name: str) -> int:
        return int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"{side}{name}"))

    for _ in range(15):
        pose = rng.uniform(lim[:, 0], lim[:, 1])
        pose[FINGER_TWIST] = 0.0  # the MuJoCo hand has no finger twist joint
        wrist = rng.uniform(-40, 40, 2)
        q = np.zeros(23)
        q[:21] = np.radians(pose[curve_of[:21]])
        q[21:] = np.radians(wrist)
        data.qpos[qidx] = q
        mujoco.mj_kinematics(model, data)
        joints = hand_joints(pose, side, wrist_deg=wrist, hand_length_m=hand_length_m)
        xr_pos = joints.positions_m
        xr_rot = Rotation.from_quat(joints.orientations_xyzw).as_matrix()

        def check(k: int, b: int, along_m: float = 0.0, xr_pos: np.ndarray = xr_pos,
                  xr_rot: np.ndarray = xr_rot) -> None:
            rot = data.xmat[b].reshape(3, 3)
            at = data.xpos[b] + rot[:, 0] * along_m
            assert np.allclose(xr_pos[k], MODEL_TO_XR @ at, atol=1e-9)
            assert np.allclose(xr_rot[k], MODEL_TO_XR @ rot @ MODEL_TO_XR.T, atol=1e-9)

        # PALM: the middle of the middle metacarpal (0.373 HL, REFERENCE.md section 4)
        check(0, body("Palm"), geo.base_pos_m["Middle"][0] - 0.373 * hand_length_m / 2)
        check(1, body("Palm"))
        thumb = geo.segments["Thumb"]
        for k, seg in enumerate(thumb):
            check(THUMB_FIRST + k, body(f"Thumb{seg.body}"))
        check(THUMB_FIRST + 3, body(f"Thumb{thumb[-1].body}"), thumb[-1].length_m)
        for f, digit in enumerate(hand.FINGERS):
            segs = geo.segments[digit]
            for k, seg in enumerate(segs):
                check(FINGER_FIRST[f] + 1 + k, body(f"{digit}{seg.body}"))
            check(FINGER_FIRST[f] + 4, body(f"{digit}{segs[-1].body}"), segs[-1].length_m)
