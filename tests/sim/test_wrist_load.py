"""The shipped puppet rig's wrist: the hand's weight (from the MuJoCo puppet model's
masses) against the wrist servos' continuous torque, and the Goal PWM cap that the
[heat] tiers use, applied by the puppet's physics (docs/hardware.md, "Heat")."""

from __future__ import annotations

import threading

import mujoco
import numpy as np
import pytest

from firmware_protocol.dynamixel import MODELS, ErrorCode, Reg
from handrig.config.rig import RigConfig, ServoCalibration, load_rig_config
from handrig.devices.servo.positions import deg_to_ticks
from sim.dxl_bus import servos_from_rig
from sim.dxl_thermal import steady_temperature_c
from sim.hand_model import REFERENCE_HAND_LENGTH_M, hand_model_xml
from sim.puppet import Puppet

G = 9.81
CONTINUOUS_SHARE = 0.20  # ROBOTIS: continuous torque ~ 20 % of the stall torque


def worst_gravity_torque_nm(joint: str) -> float:
    """The largest torque the hand's weight puts on ``joint`` over every gravity
    direction (the forearm turns): mass below the joint x g x its centre of mass's
    distance from the joint axis."""
    m = mujoco.MjModel.from_xml_string(hand_model_xml("ri", REFERENCE_HAND_LENGTH_M))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, joint)
    body = m.jnt_bodyid[j]
    r = d.subtree_com[body] - d.xanchor[j]
    axis = d.xaxis[j]
    return float(m.body_subtreemass[body] * G * np.linalg.norm(r - np.dot(r, axis) * axis))


@pytest.mark.parametrize("joint", ["riWristFlexion", "riWristDeviation"])
def test_the_shipped_wrist_servos_hold_the_hand_within_their_continuous_torque(joint: str) -> None:
    torque = worst_gravity_torque_nm(joint)
    assert 0.15 < torque < 0.25  # 0.45 kg at ~44 mm from the wrist axes
    cal = next(s for s in load_rig_config().servos if s.joint == joint)
    info = MODELS[cal.model]
    continuous = CONTINUOUS_SHARE * info.stall_torque_nm * cal.gear_ratio
    assert torque < continuous / 2, (cal.model, torque, continuous)  # 2x margin at least
    # the XL330 it replaces would hold it at 1.9x its continuous torque
    xl330 = MODELS["XL330-M288"]
    assert torque > 1.5 * CONTINUOUS_SHARE * xl330.stall_torque_nm
    # and the servo's steady temperature holding it stays far from its limit
    amps = torque / info.stall_torque_nm * info.stall_current_a
    volts = info.nominal_voltage_dv / 10.0
    assert steady_temperature_c(cal.model, volts, amps) < 45.0


def test_goal_pwm_caps_the_effort_so_the_wrist_gives_way_to_the_load() -> None:
    cal = ServoCalibration(id=4, joint="riWristFlexion", model="XM430-W350",
                           min_deg=-60.0, max_deg=60.0)
    rig = RigConfig(servos=(cal,))
    puppet = Puppet(rig)
    servos = servos_from_rig(rig)
    puppet.attach(servos, threading.RLock())
    s = servos[0]
    assert s.get(Reg.GOAL_PWM) == s.get(Reg.PWM_LIMIT) == 885  # full effort at power-on
    assert s.write(int(Reg.TORQUE_ENABLE), b"\x01") == 0
    assert s.write(int(Reg.GOAL_POSITION), deg_to_ticks(cal, 0.0).to_bytes(4, "little")) == 0
    puppet.step(1000)
    held = puppet.joint_deg("riWristFlexion")
    assert abs(held) < 5.0  # full effort: the hand is held level
    full_ma = abs(s.get(Reg.PRESENT_CURRENT)) * s.info.current_unit_ma
    # 2 % of full PWM: ~0.08 N m, less than the hand's 0.19 N m: the wrist gives way
    assert s.write(int(Reg.GOAL_PWM), (18).to_bytes(2, "little", signed=True)) == 0
    puppet.step(1500)
    sagged = puppet.joint_deg("riWristFlexion")
    assert sagged > held + 20.0
    capped_ma = abs(s.get(Reg.PRESENT_CURRENT)) * s.info.current_unit_ma
    assert capped_ma < 0.6 * full_ma  # the current, and the heat, fall with the cap
    # a Goal PWM above PWM Limit is the servo's Data Limit error
    s.set(Reg.PWM_LIMIT, 500)
    assert s.write(int(Reg.GOAL_PWM), (600).to_bytes(2, "little", signed=True)) \
        == ErrorCode.DATA_LIMIT
    assert s.write(int(Reg.GOAL_PWM), (-500).to_bytes(2, "little", signed=True)) == 0
