"""The shared MJCF hand: names, masses, mirroring and the sign of every joint axis."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from handrig.hand import DOF_NAMES, Hand
from sim.hand_model import (
    ActuatorParams,
    PassiveParams,
    dof_qpos_indices,
    gravity_in_forearm,
    hand_geometry,
    hand_model_xml,
    ramp_ctrl,
)

ZERO = PassiveParams(
    rest_deg=dict.fromkeys(DOF_NAMES["ri"], 0.0),
    ks_nm_per_rad=dict.fromkeys(DOF_NAMES["ri"], 0.0),
    kd_nms_per_rad=dict.fromkeys(DOF_NAMES["ri"], 0.0),
)
# A relaxed-looking pose (degrees, vocabulary convention) to test torques at.
POSE = {"ThumbCMCy": 42, "ThumbCMCz": 28, "ThumbMCPz": 36, "ThumbIPz": 24,
        "MCPy": 40, "PIPy": 50, "DIPy": 35}


def _pose_deg(hand: Hand) -> np.ndarray:
    out = []
    for name in DOF_NAMES[hand]:
        stem = name[2:]
        out.append(POSE.get(stem, POSE.get(stem[-4:], 0.0)))
    return np.array(out, dtype=float)


def _gravity_torque(hand: Hand, inc: float, rot: float) -> dict[str, float]:
    m = mujoco.MjModel.from_xml_string(hand_model_xml(hand, passive=ZERO, mujoco_limits=False))
    d = mujoco.MjData(m)
    idx = dof_qpos_indices(m, hand)
    m.opt.gravity[:] = gravity_in_forearm(inc, rot, hand)
    d.qpos[idx] = np.radians(_pose_deg(hand))
    mujoco.mj_forward(m, d)
    torque = -d.qfrc_bias[idx]
    return {n[2:]: float(t) for n, t in zip(DOF_NAMES[hand], torque, strict=True)}


def test_joint_names_are_the_vocabulary() -> None:
    for hand in ("ri", "le"):
        m = mujoco.MjModel.from_xml_string(hand_model_xml(hand, passive=ZERO))
        names = {m.joint(i).name for i in range(m.njnt)}
        assert names == set(DOF_NAMES[hand])
        assert m.nq == 23


def test_masses_follow_the_table_and_scale_with_hand_length() -> None:
    g = hand_geometry(0.19)
    assert g.total_mass_kg == pytest.approx(0.45)
    index = g.segments["Index"]
    assert [s.mass_kg for s in index] == pytest.approx([0.0152, 0.0066, 0.0035])
    assert index[0].length_m == pytest.approx(0.245 * 0.19)
    big = hand_geometry(0.19 * 1.2)
    assert big.total_mass_kg == pytest.approx(0.45 * 1.2**3)
    assert big.segments["Index"][1].length_m == pytest.approx(0.143 * 0.19 * 1.2)
    m = mujoco.MjModel.from_xml_string(hand_model_xml("ri", passive=ZERO))
    palm = m.body("riPalm").id
    assert m.body_subtreemass[palm] == pytest.approx(0.45)


@pytest.mark.parametrize("hand", ["ri", "le"])
def test_gravity_pushes_each_dof_the_physical_way(hand: Hand) -> None:
    down = _gravity_torque(hand, 0.0, 0.0)  # palm down
    up = _gravity_torque(hand, 0.0, 180.0)  # palm up
    thumb = _gravity_torque(hand, 0.0, 90.0)  # palm vertical, thumb up
    hang = _gravity_torque(hand, -90.0, 0.0)
    assert down["WristFlexion"] > 0 and up["WristFlexion"] < 0  # droops palmar
    assert thumb["WristDeviation"] < 0  # droops toward the little finger = ulnar
    for f in ("Index", "Middle", "Ring", "Pinky"):
        assert down[f"{f}MCPy"] > 0 and up[f"{f}MCPy"] < 0
        assert thumb[f"{f}MCPx"] < 0  # fingers fall toward the little finger side
        for j in ("MCPy", "PIPy", "DIPy"):
            assert hang[f"{f}{j}"] < 0  # hanging down straightens them
    assert down["ThumbCMCz"] > 0  # thumb drops palmar = CMC flexion
    assert thumb["ThumbCMCy"] < 0  # thumb drops toward the index = less abduction
    assert thumb["ThumbMCPz"] > 0 and thumb["ThumbIPz"] > 0  # thumb curls down


def test_left_hand_is_the_mirror_image() -> None:
    for inc, rot in ((0, 0), (0, 90), (-90, 0), (30, -120)):
        ri, le = _gravity_torque("ri", inc, rot), _gravity_torque("le", inc, rot)
        assert le == pytest.approx(ri, abs=1e-12)
    assert gravity_in_forearm(0, 90, "ri")[1] == pytest.approx(-9.81)
    assert gravity_in_forearm(0, 90, "le")[1] == pytest.approx(9.81)


def test_gravity_vector_for_the_named_orientations() -> None:
    np.testing.assert_allclose(gravity_in_forearm(0, 0), [0, 0, -9.81], atol=1e-12)
    np.testing.assert_allclose(gravity_in_forearm(0, 180), [0, 0, 9.81], atol=1e-12)
    np.testing.assert_allclose(gravity_in_forearm(-90, 37), [9.81, 0, 0], atol=1e-12)
    np.testing.assert_allclose(gravity_in_forearm(90, 0), [-9.81, 0, 0], atol=1e-12)


def test_actuated_joint_tracks_its_goal_at_limited_speed() -> None:
    name = "riIndexMCPy"
    act = ActuatorParams(kp_nm_per_rad=2.0, kv_nms_per_rad=0.05, force_limit_nm=1.0,
                         max_speed_rad_s=2.0)
    m = mujoco.MjModel.from_xml_string(
        hand_model_xml("ri", passive=ZERO, actuated={name: act}))
    d = mujoco.MjData(m)
    assert m.nu == 1 and m.actuator(0).name == name
    m.opt.gravity[:] = 0.0
    goal, qadr = np.array([1.0]), m.joint(name).qposadr[0]
    steps = int(0.25 / m.opt.timestep)
    for _ in range(steps):
        ramp_ctrl(d.ctrl, goal, act.max_speed_rad_s * m.opt.timestep)
        mujoco.mj_step(m, d)
    assert d.ctrl[0] == pytest.approx(0.5, abs=0.01)  # 2 rad/s for 0.25 s
    for _ in range(2 * steps):
        ramp_ctrl(d.ctrl, goal, act.max_speed_rad_s * m.opt.timestep)
        mujoco.mj_step(m, d)
    assert d.qpos[qadr] == pytest.approx(1.0, abs=0.02)
    with pytest.raises(ValueError, match="not DOFs"):
        hand_model_xml("ri", passive=ZERO, actuated={"leIndexMCPy": act})


def test_both_hands_in_one_model_keep_each_hand_s_joints_and_actuators():
    import mujoco

    from sim.hand_model import ActuatorParams, two_hands_xml

    act = {"riIndexMCPy": ActuatorParams(), "leIndexMCPy": ActuatorParams()}
    m = mujoco.MjModel.from_xml_string(two_hands_xml(actuated=act))
    names = {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, i) for i in range(m.njnt)}
    assert names == set(DOF_NAMES["ri"]) | set(DOF_NAMES["le"])  # 23 DOFs a hand
    assert {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, i)
            for i in range(m.nu)} == set(act)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    ri = d.xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "riPalm")]
    le = d.xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "lePalm")]
    assert le[1] - ri[1] == pytest.approx(0.3)  # side by side, the forearms 0.3 m apart
