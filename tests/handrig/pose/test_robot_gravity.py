"""Gravity on a robot hand's joints (handrig.pose.gravity): the compiled torques against
MuJoCo's own, the goal offsets, and the ``[robot] gravity`` keys of a rig file."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest

from handrig.app.parts import build_parts
from handrig.app.robot_gravity import build_gravity, gravity_chain
from handrig.config.rig_files import RIGS_DIR
from handrig.devices.servo.models import holding_stiffness_nm_per_rad, torque_cap_nm
from handrig.errors import ConfigError
from handrig.pose.gravity import GravityCompensation
from handrig.pose.robot_rig import RobotRigConfig, load_rig

mujoco = pytest.importorskip("mujoco")


def _leap(**robot: object) -> RobotRigConfig:
    rig = load_rig("leap")
    assert isinstance(rig, RobotRigConfig) and rig.robot is not None
    return dataclasses.replace(rig, robot=dataclasses.replace(rig.robot, **robot))


def _limits(rig: RobotRigConfig) -> tuple[np.ndarray, np.ndarray]:
    return (np.array([s.min_deg for s in rig.servos]), np.array([s.max_deg for s in rig.servos]))


@pytest.mark.parametrize("preset", ["leap", "orca"])
def test_torques_are_mujocos_at_any_pose_and_orientation(preset: str) -> None:
    """The compiled pass over the chain gives MuJoCo's qfrc_bias at rest, joint by joint,
    at random poses over the whole range and gravity from random directions."""
    rig = load_rig(preset)
    assert isinstance(rig, RobotRigConfig) and rig.robot is not None
    chain = gravity_chain(rig.robot.model)
    m = mujoco.MjModel.from_xml_path(rig.robot.model)
    d = mujoco.MjData(m)
    assert chain.joint_names == tuple(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
                                      for j in range(m.njnt))
    n = len(chain.joint_names)
    comp = GravityCompensation(chain, chain.joint_names, stiffness_nm_per_rad=np.ones(n),
                               torque_limit_nm=np.ones(n), low_deg=np.full(n, -180.0),
                               high_deg=np.full(n, 180.0), gravity_mps2=(0.0, 0.0, -9.81))
    rng = np.random.default_rng(3)
    largest = 0.0
    for _ in range(40):
        g = rng.normal(size=3)
        g *= 9.81 / np.linalg.norm(g)
        m.opt.gravity[:] = g
        comp.set_gravity(g)
        q = rng.uniform(m.jnt_range[:, 0], m.jnt_range[:, 1])
        d.qpos[:], d.qvel[:] = q, 0.0
        mujoco.mj_forward(m, d)
        np.testing.assert_allclose(comp.joint_torques_nm(q), d.qfrc_bias, atol=1e-9)
        largest = max(largest, float(np.abs(d.qfrc_bias).max()))
    assert largest > 0.03  # the fingers weigh something: the comparison is not 0 == 0


def test_goals_move_by_torque_over_stiffness_within_the_limits() -> None:
    rig = _leap(gravity=True)
    low, high = _limits(rig)
    comp = build_gravity(rig, low, high)
    assert comp is not None
    goals = low + 0.3 * (high - low)
    sent = comp.apply(goals).copy()
    tau = comp.tau_nm[comp.servo_joint]
    assert np.abs(tau).max() > 0.01
    expected = goals + np.degrees(np.clip(tau, -comp.torque_limit_nm, comp.torque_limit_nm)
                                  / comp.stiffness_nm_per_rad)
    np.testing.assert_allclose(sent, np.clip(expected, low, high), atol=1e-9)
    assert np.abs(sent - goals).max() > 0.3  # a measurable offset at 350 mA, P 600
    # at the limits a goal stays inside them
    np.testing.assert_array_less(comp.apply(high) - 1e-9, high)
    np.testing.assert_array_less(low - 1e-9, comp.apply(low))
    # turned upside down, every offset turns sign
    comp.set_gravity(-np.asarray(rig.robot.gravity_mps2))  # type: ignore[union-attr]
    flipped = comp.apply(goals) - goals
    np.testing.assert_allclose(flipped, -(sent - goals), atol=1e-9)


def test_a_non_finite_goal_passes_and_spoils_no_other() -> None:
    rig = _leap(gravity=True)
    low, high = _limits(rig)
    comp = build_gravity(rig, low, high)
    assert comp is not None
    goals = low + 0.3 * (high - low)
    clean = comp.apply(goals).copy()
    goals[5] = math.nan
    out = comp.apply(goals)
    assert math.isnan(out[5])
    finger = [k for k, s in enumerate(rig.servos) if s.joint.startswith("mf_")]
    others = [k for k in range(len(goals)) if k not in finger]
    np.testing.assert_allclose(out[others], clean[others], atol=1e-12)  # other chains
    assert np.isfinite(out[[k for k in finger if k != 5]]).all()


def test_stiffness_and_cap_follow_the_servo_model() -> None:
    rig = _leap()
    servo = rig.servos[1]  # XC330-M288: 0.93 N m, 1.80 A stall
    k = holding_stiffness_nm_per_rad(servo, 600)
    assert k == pytest.approx(0.93 * 600 / 128 / 885 * 4096 / (2 * math.pi))
    assert holding_stiffness_nm_per_rad(servo, None) == pytest.approx(k * 1100 / 600)
    assert torque_cap_nm(servo, 350) == pytest.approx(0.93 * 0.35 / 1.80)
    assert torque_cap_nm(servo, None) == pytest.approx(0.93)


def test_gravity_is_off_unless_the_rig_file_asks() -> None:
    rig = _leap(gravity=False)
    assert build_gravity(rig, *_limits(rig)) is None
    assert load_rig("orca").robot.gravity is False  # type: ignore[union-attr]


def _rig_file(tmp_path: Path, robot_lines: str) -> Path:
    """The LEAP preset with ``robot_lines`` added to its [robot] table, paths absolute."""
    text = (RIGS_DIR / "leap.toml").read_text()
    model = (RIGS_DIR / "../../data/robots/leap_hand/right_hand.xml").resolve()
    text = re.sub(r'^model = ".*"$', f'model = "{model}"', text, count=1, flags=re.M)
    text = re.sub(r'^retarget = ".*"$', f'retarget = "{RIGS_DIR / "leap_retarget.toml"}"',
                  text, flags=re.M)
    text = re.sub(r"^gravity(_direction)? = .*$", "", text, flags=re.M)
    text = text.replace("[robot]\n", "[robot]\n" + robot_lines + "\n", 1)
    path = tmp_path / "leap_gravity.toml"
    path.write_text(text)
    return path


def test_the_rig_file_key_turns_it_on_in_the_run_parts(tmp_path: Path) -> None:
    parts = build_parts(_rig_file(tmp_path, "gravity = true\ngravity_direction = [1, 0, 0]"))
    assert parts.gravity is not None
    np.testing.assert_allclose(parts.gravity.gravity_mps2, [9.80665, 0.0, 0.0])
    np.testing.assert_array_equal(parts.gravity.low_deg, parts.pipeline.servo_low)
    assert build_parts("leap").gravity is not None  # the shipped preset holds its fingers up
    assert build_parts("orca").gravity is None


@pytest.mark.parametrize(("lines", "key", "says"), [
    ('gravity = "yes"', "gravity", "true or false"),
    ("gravity = 1", "gravity", "true or false"),
    ("gravity_direction = [0, 0, 0]", "gravity_direction", "not all 0"),
    ("gravity_direction = [0, -1]", "gravity_direction", "3 numbers"),
    ('gravity_direction = [0, "down", 0]', "gravity_direction", "number"),
])
def test_a_bad_gravity_key_names_file_key_and_fix(tmp_path: Path, lines: str, key: str,
                                                   says: str) -> None:
    path = _rig_file(tmp_path, lines)
    with pytest.raises(ConfigError) as info:
        load_rig(path)
    text = str(info.value)
    assert key in text and str(path) in text and says in text, text


LEAP_FOREARM = ((1.0, 0.0, 0.0), (0.0, 0.0, -1.0))  # LEAP's fingers along +x, palm to +z


@pytest.mark.parametrize(("inclination", "rotation"), [(0.0, 0.0), (30.0, 90.0),
                                                        (-60.0, 180.0), (10.0, -45.0)])
def test_on_an_arm_gravity_follows_the_forearm(inclination: float, rotation: float) -> None:
    """``gravity_from = "forearm"``: each call's forearm angles give gravity in the model
    frame, the same offsets as a hand fixed in that orientation."""
    from sim.hand_model import gravity_in_forearm  # the puppet's own convention

    rig = _leap(gravity=True, gravity_from="forearm", forearm_axes=LEAP_FOREARM)
    low, high = _limits(rig)
    arm = build_gravity(rig, low, high)
    table = build_gravity(rig, low, high)
    assert arm is not None and table is not None and arm.forearm_to_model is not None
    assert table.forearm_to_model is not None
    table.forearm_to_model = None  # the same servos, gravity set by hand
    down = np.array(rig.robot.forearm_to_model) @ gravity_in_forearm(  # type: ignore[union-attr]
        inclination, rotation, g_mps2=9.80665)
    table.set_gravity(down)
    goals = low + 0.3 * (high - low)
    np.testing.assert_allclose(arm.apply(goals, inclination, rotation), table.apply(goals),
                               atol=1e-9)
    np.testing.assert_allclose(arm.gravity_mps2, down, atol=1e-9)


def test_leap_level_and_palm_down_is_the_model_upside_down() -> None:
    """The LEAP model as drawn has its palm up (gravity -z pulls the fingers toward the
    back of the hand): a level forearm, palm down, is gravity +z in the model."""
    from sim.hand_model import gravity_in_forearm

    rig = _leap(gravity_from="forearm", forearm_axes=LEAP_FOREARM)
    down = np.array(rig.robot.forearm_to_model) @ gravity_in_forearm(0.0, 0.0)  # type: ignore[union-attr]
    np.testing.assert_allclose(down / np.linalg.norm(down), [0.0, 0.0, 1.0], atol=1e-12)


@pytest.mark.parametrize(("lines", "key", "says"), [
    ('gravity_from = "arm"', "gravity_from", '"table" or "forearm"'),
    ('gravity_from = "forearm"', "forearm_axes", "two axes"),
    ('gravity_from = "forearm"\nforearm_axes = [[1, 0, 0], [1, 0, 0]]', "forearm_axes",
     "right angles"),
    ('gravity_from = "forearm"\nforearm_axes = [[2, 0, 0], [0, 0, 1]]', "forearm_axes",
     "unit"),
])
def test_a_bad_forearm_mount_names_key_and_fix(tmp_path: Path, lines: str, key: str,
                                               says: str) -> None:
    path = _rig_file(tmp_path, lines)
    with pytest.raises(ConfigError) as info:
        load_rig(path)
    text = str(info.value)
    assert key in text and str(path) in text and says in text, text


def test_a_forearm_mount_loads_from_the_rig_file(tmp_path: Path) -> None:
    parts = build_parts(_rig_file(
        tmp_path, 'gravity = true\ngravity_from = "forearm"\n'
                  "forearm_axes = [[1, 0, 0], [0, 0, -1]]"))
    assert parts.gravity is not None and parts.gravity.forearm_to_model is not None
    np.testing.assert_allclose(parts.gravity.forearm_to_model,
                               [[1, 0, 0], [0, -1, 0], [0, 0, -1]], atol=1e-12)


def test_the_goals_a_bus_holds_give_back_the_loops_goals() -> None:
    """A loop that starts on goals the bus holds (or eases a servo back from its last
    goal) takes the offsets off: it does not count them twice."""
    rig = _leap(gravity=True)
    low, high = _limits(rig)
    comp = build_gravity(rig, low, high)
    assert comp is not None
    goals = low + 0.3 * (high - low)
    sent = comp.apply(goals).copy()
    assert np.abs(sent - goals).max() > 0.3
    np.testing.assert_allclose(comp.loop_goals(sent), goals, atol=0.005)
    held = sent.copy()
    held[3] = math.nan  # a servo the bus never sent a goal keeps its NaN
    back = comp.loop_goals(held)
    assert math.isnan(back[3]) and np.isfinite(np.delete(back, 3)).all()
