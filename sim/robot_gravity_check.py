"""How far a robot hand's fingers stop from their goals under gravity, in the emulator.

The robot rig's servos are commissioned as a run commissions them (its
``[servo_settings]``: operating mode, Current Limit and Goal Current, P and D gains),
each pose's goals are written to Goal Position (compensated by
:class:`handrig.pose.gravity.GravityCompensation` or not), the MuJoCo model is stepped
until it settles, and each joint's angle is compared with the goal it was meant to
reach. Simulated time only: the figures do not depend on the machine's load.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from firmware_protocol.dynamixel import Reg
from handrig.devices.servo.models import current_limit_units, servo_settings_for
from handrig.devices.servo.positions import deg_to_ticks
from handrig.pose.gravity import GravityCompensation
from handrig.pose.robot_rig import RobotRigConfig
from sim.dxl_bus import servos_from_rig
from sim.dxl_servo import EmulatedServo
from sim.puppet import Puppet

FloatArray = NDArray[np.float64]
# How far each pose flexes the joints from 0 toward their upper limits: open .. half
# closed, where LEAP's fingers and thumb touch nothing (the emulator in free fall
# then holds every joint within 0.05 deg of its goal: goals are whole ticks).
POSE_FRACTIONS: tuple[float, ...] = (0.1, 0.25, 0.4)


@dataclass(frozen=True)
class GravityError:
    """Per pose (rows) and servo (columns, bus order): goal minus settled angle, degrees."""

    joints: tuple[str, ...]
    error_deg: FloatArray  # (poses, servos)

    @property
    def per_joint_deg(self) -> FloatArray:
        """Each servo's mean absolute error over the poses."""
        return np.asarray(np.abs(self.error_deg).mean(axis=0))

    @property
    def rms_deg(self) -> float:
        return float(np.sqrt(np.mean(self.error_deg ** 2)))

    @property
    def max_deg(self) -> float:
        return float(np.abs(self.error_deg).max())


def _write(s: EmulatedServo, reg: Reg, value: int, size: int) -> None:
    err = s.write(int(reg), int(value).to_bytes(size, "little", signed=True))
    if err:
        raise RuntimeError(f"servo {s.id}: write of {reg.name} = {value} refused ({err})")


def commission(rig: RobotRigConfig, servos: dict[int, EmulatedServo],
               goal_current_ma: int | None = None) -> None:
    """Write the rig's ``[servo_settings]`` to each servo, then torque on; a given
    ``goal_current_ma`` replaces the rig's current (Current Limit and Goal Current)."""
    for cal in rig.servos:
        s, st = servos[cal.id], servo_settings_for(rig, cal.id)
        _write(s, Reg.OPERATING_MODE, st.operating_mode, 1)
        current = goal_current_ma if goal_current_ma is not None else st.current_limit_ma
        units = current_limit_units(current, cal.model)
        if units is not None:
            _write(s, Reg.CURRENT_LIMIT, units, 2)
            _write(s, Reg.GOAL_CURRENT, units, 2)
        if st.position_p_gain is not None:
            _write(s, Reg.POSITION_P_GAIN, st.position_p_gain, 2)
        if st.position_d_gain is not None:
            _write(s, Reg.POSITION_D_GAIN, st.position_d_gain, 2)
        _write(s, Reg.TORQUE_ENABLE, 1, 1)


def poses_deg(rig: RobotRigConfig, fractions: tuple[float, ...] = POSE_FRACTIONS
              ) -> FloatArray:
    """(poses, servos) goals: a joint whose servo range is about symmetric around 0 (a
    finger's side-to-side) at 0, one whose range holds 0 at ``fraction`` of its upper
    limit, any other at ``fraction`` of its range."""
    low = np.array([c.min_deg for c in rig.servos])
    high = np.array([c.max_deg for c in rig.servos])
    side = (low < 0.0) & (high > 0.0) & (np.abs(low + high) < 0.1 * (high - low))
    start = np.where((low <= 0.0) & (high > 0.0), 0.0, low)
    return np.array([np.where(side, 0.0, start + f * (high - start)) for f in fractions])


def gravity_error(rig: RobotRigConfig, compensation: GravityCompensation | None, *,
                  poses: FloatArray | None = None, settle_s: float = 1.0,
                  goal_current_ma: int | None = None,
                  emulator_gravity: bool = True) -> GravityError:
    """Goal minus settled angle of every servo's joint at each pose (default
    :func:`poses_deg`), with ``compensation`` applied to the goals written (None: the
    goals as they are). ``emulator_gravity=False``: the emulated hand in free fall,
    what is left is the emulator's own error (ticks, friction, contacts)."""
    puppet = Puppet(rig)
    if not emulator_gravity:
        puppet.set_gravity((0.0, 0.0, 0.0))
    servo_list = servos_from_rig(rig)
    puppet.attach(servo_list, threading.RLock())
    servos = {s.id: s for s in servo_list}
    commission(rig, servos, goal_current_ma)
    steps = max(1, round(settle_s / puppet.timestep_s))
    errors = []
    for goals in poses_deg(rig) if poses is None else poses:
        sent = goals if compensation is None else compensation.apply(goals)
        for cal, goal in zip(rig.servos, sent, strict=True):
            _write(servos[cal.id], Reg.GOAL_POSITION, deg_to_ticks(cal, float(goal)), 4)
        puppet.step(steps)
        angles = puppet.joint_angles_deg()
        errors.append([g - angles[c.joint] for c, g in zip(rig.servos, goals, strict=True)])
    return GravityError(tuple(c.joint for c in rig.servos), np.array(errors))
