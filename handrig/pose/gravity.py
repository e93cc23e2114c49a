"""Gravity on a robot hand's joints, and the goal offsets that hold the fingers up.

A servo in position control is a spring about its goal: at rest it pushes back with
``k * (goal - angle)``, so a finger whose own weight pulls on the joint with torque
``tau`` stops ``tau / k`` short of its goal. :class:`GravityCompensation` moves each
goal by that much the other way, so the finger rests at the goal it was sent:
``goal + tau(goal) / k``, clamped to the servo's limits.

``tau`` is what the joint's motor must supply to hold the model still against
gravity (MuJoCo's ``qfrc_bias`` at zero velocity): for each hinge, the mass of
every body it carries times the lever of their centre of mass about its axis,
``-(axis x (com - anchor)) . g * m``. :class:`GravityChain` is the model as plain
arrays (bodies, their frames, masses and centres of mass, hinges), read from the
robot's MJCF by :func:`handrig.app.robot_gravity.gravity_chain`; the per-cycle step
is one compiled pass over the bodies (forward kinematics, then each body's subtree
mass and moment; its cost: docs/measurements.md). No table: the model's
own kinematics at the goal pose, at any orientation of the hand.

``k`` is the position loop's stiffness at the joint (N m/rad), ``torque_limit_nm``
what the servo can give (at its current cap): a torque beyond it is clipped,
since no goal offset makes the servo push harder than its cap.

This module imports no device code and no MuJoCo.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from handrig.errors import ConfigError

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class GravityChain:
    """A kinematic tree as arrays, in MuJoCo's conventions (body 0 is the world; a
    body's parent comes before it; its hinges, in order, rotate it about their
    anchors). Positions in metres, quaternions ``w, x, y, z``, masses in kg."""

    joint_names: tuple[str, ...]  # (nj,) the hinges, in model order
    body_parent: NDArray[np.int64]  # (nb,) -1 for the world
    body_pos: FloatArray  # (nb, 3) in the parent's frame
    body_quat: FloatArray  # (nb, 4) in the parent's frame
    body_mass: FloatArray  # (nb,)
    body_com: FloatArray  # (nb, 3) centre of mass in the body's frame
    body_joint_start: NDArray[np.int64]  # (nb + 1,) body b's hinges: start[b]:start[b + 1]
    joint_pos: FloatArray  # (nj, 3) anchor in its body's frame
    joint_axis: FloatArray  # (nj, 3) unit axis in its body's frame

    def check(self) -> None:
        nb, nj = len(self.body_parent), len(self.joint_names)
        shapes = {"body_pos": (nb, 3), "body_quat": (nb, 4), "body_mass": (nb,),
                  "body_com": (nb, 3), "body_joint_start": (nb + 1,), "joint_pos": (nj, 3),
                  "joint_axis": (nj, 3)}
        for key, shape in shapes.items():
            if np.shape(getattr(self, key)) != shape:
                raise ConfigError(f"gravity chain: {key} has shape "
                                  f"{np.shape(getattr(self, key))}, expected {shape}")
        if nb and (self.body_parent[0] != -1
                   or np.any(self.body_parent[1:] >= np.arange(1, nb))
                   or np.any(self.body_parent[1:] < 0)):
            raise ConfigError("gravity chain: every body's parent must come before it")
        if self.body_joint_start[0] != 0 or self.body_joint_start[-1] != nj or np.any(
                np.diff(self.body_joint_start) < 0):
            raise ConfigError("gravity chain: body_joint_start must run 0..joints in order")

    def joint_index(self, name: str) -> int:
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise ConfigError("no hinge of that name in the gravity model", value=name,
                              allowed=", ".join(self.joint_names)) from None


@njit(cache=True, nogil=True, inline="always")
def _rotate(w: float, x: float, y: float, z: float, v0: float, v1: float, v2: float
            ) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """``R(q) v`` for a unit quaternion ``q = (w, x, y, z)``."""
    tx = 2.0 * (y * v2 - z * v1)
    ty = 2.0 * (z * v0 - x * v2)
    tz = 2.0 * (x * v1 - y * v0)
    return (v0 + w * tx + (y * tz - z * ty), v1 + w * ty + (z * tx - x * tz),
            v2 + w * tz + (x * ty - y * tx))


@njit(cache=True, nogil=True, inline="always")
def _quat_mul(a0: float, a1: float, a2: float, a3: float, b0: float, b1: float, b2: float,
              b3: float) -> tuple[float, float, float, float]:  # pragma: no cover
    return (a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3, a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1, a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0)


@njit(cache=True, nogil=True)
def gravity_torques(q_rad: Any, gravity: Any, parent: Any, body: Any, jstart: Any,
                    joint: Any, scratch: Any, out: Any) -> None:  # pragma: no cover
    """The torque each hinge's motor must give to hold the tree still at ``q_rad``
    under ``gravity`` (m/s^2, world frame), into ``out`` (nj,). ``body`` (nb, 11) packs
    each body's position and quaternion in its parent's frame, its mass and its centre
    of mass in its own frame; ``joint`` (nj, 6) each hinge's anchor and unit axis in
    its body's frame. ``scratch`` (nb + nj, 11) is written: per body its world position
    and quaternion, subtree mass and first moment; per hinge its world anchor and axis."""
    nb = parent.shape[0]
    x = scratch  # rows 0..nb-1: bodies (pos 0:3, quat 3:7, msub 7, mcom 8:11)
    x[0, 0:7] = 0.0
    x[0, 3] = 1.0
    for b in range(1, nb):
        p = parent[b]
        pw, px, py, pz = x[p, 3], x[p, 4], x[p, 5], x[p, 6]
        v0, v1, v2 = _rotate(pw, px, py, pz, body[b, 0], body[b, 1], body[b, 2])
        x0, x1, x2 = x[p, 0] + v0, x[p, 1] + v1, x[p, 2] + v2
        qw, qx, qy, qz = _quat_mul(pw, px, py, pz, body[b, 3], body[b, 4], body[b, 5],
                                   body[b, 6])
        for j in range(jstart[b], jstart[b + 1]):
            r = nb + j
            v0, v1, v2 = _rotate(qw, qx, qy, qz, joint[j, 0], joint[j, 1], joint[j, 2])
            a0, a1, a2 = x0 + v0, x1 + v1, x2 + v2
            x[r, 0], x[r, 1], x[r, 2] = a0, a1, a2
            x[r, 3], x[r, 4], x[r, 5] = _rotate(qw, qx, qy, qz, joint[j, 3], joint[j, 4],
                                                joint[j, 5])
            half = 0.5 * q_rad[j]
            s = math.sin(half)
            qw, qx, qy, qz = _quat_mul(qw, qx, qy, qz, math.cos(half), joint[j, 3] * s,
                                       joint[j, 4] * s, joint[j, 5] * s)
            norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
            qw, qx, qy, qz = qw / norm, qx / norm, qy / norm, qz / norm
            v0, v1, v2 = _rotate(qw, qx, qy, qz, joint[j, 0], joint[j, 1], joint[j, 2])
            x0, x1, x2 = a0 - v0, a1 - v1, a2 - v2
        x[b, 0], x[b, 1], x[b, 2] = x0, x1, x2
        x[b, 3], x[b, 4], x[b, 5], x[b, 6] = qw, qx, qy, qz
    for b in range(nb):
        v0, v1, v2 = _rotate(x[b, 3], x[b, 4], x[b, 5], x[b, 6], body[b, 8], body[b, 9],
                             body[b, 10])
        m = body[b, 7]
        x[b, 7] = m
        x[b, 8], x[b, 9], x[b, 10] = m * (x[b, 0] + v0), m * (x[b, 1] + v1), m * (x[b, 2] + v2)
    for b in range(nb - 1, 0, -1):  # each body's subtree: its mass and first moment
        p = parent[b]
        for i in range(7, 11):
            x[p, i] += x[b, i]
    for b in range(1, nb):
        for j in range(jstart[b], jstart[b + 1]):
            r = nb + j
            # the subtree's moment about the anchor, sum m (com - anchor)
            r0 = x[b, 8] - x[b, 7] * x[r, 0]
            r1 = x[b, 9] - x[b, 7] * x[r, 1]
            r2 = x[b, 10] - x[b, 7] * x[r, 2]
            c0 = x[r, 4] * r2 - x[r, 5] * r1
            c1 = x[r, 5] * r0 - x[r, 3] * r2
            c2 = x[r, 3] * r1 - x[r, 4] * r0
            out[j] = -(c0 * gravity[0] + c1 * gravity[1] + c2 * gravity[2])


@njit(cache=True, nogil=True)
def compensate_goals(goals_deg: Any, servo_joint: Any, stiffness: Any, torque_limit: Any,
                     low_deg: Any, high_deg: Any, q_rad: Any, tau: Any,
                     out: Any) -> None:  # pragma: no cover - compiled
    """``out[k] = clip(goal[k] + deg(clip(tau[joint k], +-limit) / k), low, high)`` with
    ``tau`` already computed at ``q_rad``; a non-finite goal passes through unchanged
    (the bus's own check refuses it), as does one whose torque is not finite."""
    for k in range(goals_deg.shape[0]):
        g = goals_deg[k]
        t = tau[servo_joint[k]]
        if not (math.isfinite(g) and math.isfinite(t)):
            out[k] = g
            continue
        lim = torque_limit[k]
        if t > lim:
            t = lim
        elif t < -lim:
            t = -lim
        v = g + math.degrees(t / stiffness[k])
        if v < low_deg[k]:
            v = low_deg[k]
        elif v > high_deg[k]:
            v = high_deg[k]
        out[k] = v


@njit(cache=True, nogil=True)
def compensated_goals(goals_deg: Any, servo_joint: Any, stiffness: Any, torque_limit: Any,
                      low_deg: Any, high_deg: Any, gravity: Any, parent: Any, body: Any,
                      jstart: Any, joint: Any, scratch: Any, q_rad: Any, tau: Any,
                      out: Any) -> None:  # pragma: no cover - compiled
    """One call per cycle: the chain at the goals (a servo's joint at its goal, 0 for a
    non-finite one; joints no servo drives keep what ``q_rad`` holds), its holding
    torques into ``tau``, the compensated goals into ``out``. ``body`` (nb, 11) packs
    position, quaternion, mass and centre of mass; ``joint`` (nj, 6) anchor and axis;
    ``scratch`` (nb + nj, 11) is written."""
    for k in range(goals_deg.shape[0]):
        g = goals_deg[k]
        q_rad[servo_joint[k]] = math.radians(g) if math.isfinite(g) else 0.0
    gravity_torques(q_rad, gravity, parent, body, jstart, joint, scratch, tau)
    compensate_goals(goals_deg, servo_joint, stiffness, torque_limit, low_deg, high_deg,
                     q_rad, tau, out)


class GravityCompensation:
    """Goal offsets that cancel gravity's pull on each servo's joint (module docstring).

    ``servo_joints``: the hinge each servo drives, bus order; ``stiffness_nm_per_rad``
    and ``torque_limit_nm`` per servo, at the joint; ``low_deg``/``high_deg`` the
    servos' limits (a compensated goal never leaves them); ``gravity_mps2``: gravity
    in the model's world frame (the hand's orientation), :meth:`set_gravity` to move it.
    ``forearm_to_model`` (3x3, forearm-frame vectors into the model's frame): the hand
    rides on the forearm, and each :meth:`apply` takes gravity from the forearm's
    inclination and rotation (:mod:`handrig.pose.orientation`'s forearm frame: x
    distal, z dorsal; up is ``(sin i, cos i sin r, cos i cos r)`` there) instead.
    :meth:`apply` allocates nothing.
    """

    def __init__(self, chain: GravityChain, servo_joints: Sequence[str], *,
                 stiffness_nm_per_rad: ArrayLike, torque_limit_nm: ArrayLike,
                 low_deg: ArrayLike, high_deg: ArrayLike,
                 gravity_mps2: ArrayLike, forearm_to_model: ArrayLike | None = None) -> None:
        chain.check()
        self.chain = chain
        n = len(servo_joints)
        self.servo_joints = tuple(servo_joints)
        self.servo_joint = np.array([chain.joint_index(j) for j in servo_joints],
                                    dtype=np.int64)
        arrays = {}
        for key, values in (("stiffness_nm_per_rad", stiffness_nm_per_rad),
                            ("torque_limit_nm", torque_limit_nm), ("low_deg", low_deg),
                            ("high_deg", high_deg)):
            a = np.asarray(values, dtype=np.float64).copy()
            if a.shape != (n,) or not np.all(np.isfinite(a)):
                raise ConfigError(f"gravity compensation: {key} needs {n} finite values",
                                  key=key, value=list(np.ravel(a)))
            arrays[key] = a
        if np.any(arrays["stiffness_nm_per_rad"] <= 0.0) or np.any(
                arrays["torque_limit_nm"] < 0.0):
            raise ConfigError("gravity compensation: stiffness must be > 0 and torque "
                              "limits >= 0", key="stiffness_nm_per_rad",
                              value=list(arrays["stiffness_nm_per_rad"]))
        self.stiffness_nm_per_rad = arrays["stiffness_nm_per_rad"]
        self.torque_limit_nm = arrays["torque_limit_nm"]
        self.low_deg, self.high_deg = arrays["low_deg"], arrays["high_deg"]
        self.gravity_mps2 = np.zeros(3)
        self.set_gravity(gravity_mps2)
        self.g_mps2 = float(np.linalg.norm(self.gravity_mps2))
        self.forearm_to_model: FloatArray | None = None
        if forearm_to_model is not None:
            rot = np.asarray(forearm_to_model, dtype=np.float64)
            if rot.shape != (3, 3) or not np.allclose(rot @ rot.T, np.eye(3), atol=1e-3):
                raise ConfigError("forearm_to_model must be a 3x3 rotation",
                                  key="forearm_axes", value=rot.tolist())
            self.forearm_to_model = rot.copy()
        nb, nj = len(chain.body_parent), len(chain.joint_names)
        self.q_rad = np.zeros(nj)  # joints no servo drives stay at 0
        self.tau_nm = np.zeros(nj)
        self.goals_deg = np.zeros(n)
        self._body = np.ascontiguousarray(np.hstack([
            chain.body_pos, chain.body_quat, chain.body_mass[:, None], chain.body_com]))
        self._joint = np.ascontiguousarray(np.hstack([chain.joint_pos, chain.joint_axis]))
        self._scratch = np.zeros((nb + nj, 11))
        self.apply(np.clip(np.zeros(n), self.low_deg, self.high_deg))  # compiles

    def set_gravity(self, gravity_mps2: ArrayLike) -> None:
        """Gravity in the model's world frame, m/s^2 (the hand turned: gravity turned)."""
        g = np.asarray(gravity_mps2, dtype=np.float64)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ConfigError("gravity must be 3 finite numbers (m/s^2)", key="gravity_mps2",
                              value=list(np.ravel(g)))
        self.gravity_mps2[:] = g

    def joint_torques_nm(self, q_rad: FloatArray) -> FloatArray:
        """The holding torque of every hinge of the chain (model order) at ``q_rad``."""
        gravity_torques(np.ascontiguousarray(q_rad, dtype=np.float64), self.gravity_mps2,
                        self.chain.body_parent, self._body, self.chain.body_joint_start,
                        self._joint, self._scratch, self.tau_nm)
        return self.tau_nm

    def loop_goals(self, sent_deg: FloatArray) -> FloatArray:
        """The loop's goals that :meth:`apply` turned into ``sent_deg`` (what the bus
        holds), at the gravity of the last call: the offset at a goal changes little
        with the goal, so three fixed-point steps leave well under 0.01 deg. A new
        array; not for the per-cycle path (a loop's start, a servo coming back)."""
        sent = np.asarray(sent_deg, dtype=np.float64)
        goals = sent.copy()
        for _ in range(3):
            goals = sent - (self._at_gravity(goals) - goals)
        return goals

    def _at_gravity(self, goals_deg: FloatArray) -> FloatArray:
        """:meth:`apply` at the gravity set now (no forearm angles): a copy."""
        c = self.chain
        out = np.empty(len(goals_deg))
        compensated_goals(np.ascontiguousarray(goals_deg), self.servo_joint,
                          self.stiffness_nm_per_rad, self.torque_limit_nm, self.low_deg,
                          self.high_deg, self.gravity_mps2, c.body_parent, self._body,
                          c.body_joint_start, self._joint, self._scratch, self.q_rad.copy(),
                          self.tau_nm.copy(), out)
        return out

    def apply(self, goals_deg: FloatArray, inclination_deg: float = 0.0,
              rotation_deg: float = 0.0) -> FloatArray:
        """The goals to send for ``goals_deg`` (bus order, degrees): each moved by its
        joint's holding torque over its stiffness, within the servo's limits. The
        forearm's angles count only with ``forearm_to_model``. Returns an array this
        object owns (overwritten by the next call)."""
        rot = self.forearm_to_model
        if rot is not None and math.isfinite(inclination_deg) and math.isfinite(rotation_deg):
            i, r = math.radians(inclination_deg), math.radians(rotation_deg)
            up0, up1, up2 = math.sin(i), math.cos(i) * math.sin(r), math.cos(i) * math.cos(r)
            g, grav = -self.g_mps2, self.gravity_mps2
            for k in range(3):
                grav[k] = g * (rot[k, 0] * up0 + rot[k, 1] * up1 + rot[k, 2] * up2)
        c = self.chain
        compensated_goals(goals_deg, self.servo_joint, self.stiffness_nm_per_rad,
                          self.torque_limit_nm, self.low_deg, self.high_deg,
                          self.gravity_mps2, c.body_parent, self._body, c.body_joint_start,
                          self._joint, self._scratch, self.q_rad, self.tau_nm,
                          self.goals_deg)
        return self.goals_deg
