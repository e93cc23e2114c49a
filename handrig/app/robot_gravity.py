"""A robot rig's gravity compensation (``[robot] gravity = true``), built from its parts.

The robot's MJCF, compiled by MuJoCo once at start-up, gives the chain of bodies,
masses and hinges (:func:`gravity_chain`); the servos' models and settings give each
joint's stiffness and torque cap (:mod:`handrig.devices.servo.models`); the rig file
gives which way gravity points (``[robot].gravity_direction``). What runs each cycle
is :class:`handrig.pose.gravity.GravityCompensation`, with no MuJoCo in it.
"""

from __future__ import annotations

import numpy as np

from handrig.devices.servo.models import (
    holding_stiffness_nm_per_rad,
    resolve_servo_settings,
    torque_cap_nm,
)
from handrig.errors import ConfigError
from handrig.pose.gravity import GravityChain, GravityCompensation
from handrig.pose.robot_rig import RobotRigConfig


def gravity_chain(model_path: str) -> GravityChain:
    """The MJCF model's bodies and hinges as a :class:`GravityChain` (MuJoCo compiles
    the model: its defaults, inertias from geoms, frames). A model with any joint
    other than a hinge is refused (a robot hand fixed to its table has only hinges)."""
    import mujoco

    try:
        m = mujoco.MjModel.from_xml_path(model_path)
    except ValueError as exc:
        raise ConfigError(f"MuJoCo cannot load the robot model: {exc}",
                          file=model_path) from None
    hinge = mujoco.mjtJoint.mjJNT_HINGE
    for j in range(m.njnt):
        if m.jnt_type[j] != hinge:
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or f"#{j}"
            raise ConfigError("gravity compensation needs a model of hinges only",
                              file=model_path, key="robot.gravity", value=name,
                              allowed="gravity = false for this model")
    names = tuple(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or f"#{j}"
                  for j in range(m.njnt))
    # joints are numbered body by body in MuJoCo: body b's are jnt_adr .. + jnt_num
    start = np.zeros(m.nbody + 1, dtype=np.int64)
    for b in range(m.nbody):
        start[b + 1] = start[b] + int(m.body_jntnum[b])
        if m.body_jntnum[b] and int(m.body_jntadr[b]) != start[b]:
            raise ConfigError("the model's joints are not in body order", file=model_path)
    parent = m.body_parentid.astype(np.int64).copy()
    parent[0] = -1
    chain = GravityChain(
        joint_names=names, body_parent=parent, body_pos=m.body_pos.copy(),
        body_quat=m.body_quat.copy(), body_mass=m.body_mass.copy(),
        body_com=m.body_ipos.copy(), body_joint_start=start, joint_pos=m.jnt_pos.copy(),
        joint_axis=m.jnt_axis.copy())
    chain.check()
    return chain


def build_gravity(rig: RobotRigConfig, low_deg: np.ndarray, high_deg: np.ndarray
                  ) -> GravityCompensation | None:
    """The rig's gravity compensation, or None when ``[robot].gravity`` is off.
    ``low_deg``/``high_deg``: the servos' limits the pipeline keeps (bus order)."""
    robot = rig.robot
    if robot is None or not robot.gravity:
        return None
    stiffness, cap = [], []
    for s in rig.servos:
        settings = resolve_servo_settings(rig.servo_settings, s.id)
        g = s.gear_ratio  # joint = horn / g: stiffness g^2, torque g times the horn's
        stiffness.append(holding_stiffness_nm_per_rad(s, settings.position_p_gain) * g * g)
        cap.append(torque_cap_nm(s, settings.current_limit_ma) * g)
    return GravityCompensation(
        gravity_chain(robot.model), [s.joint for s in rig.servos],
        stiffness_nm_per_rad=stiffness, torque_limit_nm=cap, low_deg=low_deg,
        high_deg=high_deg, gravity_mps2=robot.gravity_mps2,
        forearm_to_model=robot.forearm_to_model if robot.gravity_from == "forearm" else None)
