"""Fingertips of the human hand model and of a robot hand, in one palm frame.

The retarget fit (:mod:`sim.retarget_fit`) compares where the human's fingertips are
with where the robot's go at the retargeted joint angles. Both hands are posed with
MuJoCo's forward kinematics (``mj_kinematics``; no dynamics, no contacts) and their
tips expressed in a **palm frame** built the same way on each hand from its straight
pose (every joint at 0: the human model's zero, the robot model's flat hand):

* origin: the mean of the matched fingers' base joints (the MCP anchors);
* x: from the origin toward the mean of those fingers' tips (distal);
* y: from the ulnar-most matched finger's base toward the index finger's base,
  made orthogonal to x (radial, toward the thumb);
* z = x × y (dorsal for a right hand).

"Matched" digits are the human digits a robot finger follows (the retarget table
says which: LEAP's ring finger follows the human little finger). Each digit's base
(its first joint) in the straight pose is kept (:attr:`HandTips.bases`, with the
straight base -> tip lengths :attr:`HandTips.digit_length_m`), so a human tip can be
carried onto the robot relative to its digit's base, scaled by the two digits'
lengths (:meth:`sim.retarget_fit.GraspModel.human_tips`).

Human tip: the end of the distal segment's axis (:mod:`sim.hand_model`). Robot tip:
on the digit's most distal body, the corner of its geoms' bounding boxes farthest
from the digit's base in the straight pose (the finger pad's far end; a model with
a ``<site name="<digit>_tip">``-like site would be more exact, none of the shipped
ones has one).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.errors import ConfigError
from sim.hand_model import dof_qpos_indices, hand_geometry, hand_model_xml

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PalmFrame:
    """A palm frame: ``local = rot.T @ (world - origin)``."""

    origin: FloatArray  # (3,)
    rot: FloatArray  # (3, 3), columns x, y, z in the world

    @classmethod
    def from_points(cls, bases: FloatArray, tips: FloatArray) -> PalmFrame:
        """From the matched fingers' bases and straight tips (k, 3), radial first."""
        origin = bases.mean(axis=0)
        x = tips.mean(axis=0) - origin
        x /= np.linalg.norm(x)
        y = bases[0] - bases[-1]
        y -= x * float(x @ y)
        y /= np.linalg.norm(y)
        z = np.cross(x, y)
        return cls(origin, np.column_stack([x, y, z]))

    def local(self, world: FloatArray) -> FloatArray:
        """World points (..., 3) in this frame."""
        out: FloatArray = (np.asarray(world) - self.origin) @ self.rot
        return out


class HandTips:
    """A hand posed by joint angles; its digits' tips in the palm frame (metres).

    Subclasses say how a pose becomes ``qpos`` (:meth:`_set`) and where each digit's
    base and tip are. ``digits``: the human digit names this hand's tips stand for,
    in order (the thumb, if any, first; fingers radial to ulnar).
    """

    digits: tuple[str, ...]
    length_m: float
    digit_length_m: FloatArray  # (digits,) straight base -> tip
    bases: FloatArray  # (digits, 3) each digit's base in the palm frame
    frame: PalmFrame

    def __init__(self, model: mujoco.MjModel, digits: Sequence[str]) -> None:
        self.model = model
        self.data = mujoco.MjData(model)
        self.digits = tuple(digits)

    # -- what a subclass provides --------------------------------------------------
    def _set(self, pose: FloatArray) -> None:
        raise NotImplementedError

    def _tip_world(self) -> FloatArray:
        raise NotImplementedError

    def _bases_world(self) -> FloatArray:
        raise NotImplementedError

    # -- shared ---------------------------------------------------------------------
    def _straight(self, pose: FloatArray) -> None:
        """Build the palm frame and the length scale from the straight pose."""
        self._set(pose)
        mujoco.mj_kinematics(self.model, self.data)
        tips, bases = self._tip_world(), self._bases_world()
        fingers = [i for i, d in enumerate(self.digits) if d != "Thumb"]
        if len(fingers) < 2:
            raise ConfigError("a hand needs two fingers besides the thumb for its palm frame",
                              allowed=f"digits {', '.join(self.digits)}")
        self.frame = PalmFrame.from_points(bases[fingers], tips[fingers])
        lengths = np.linalg.norm(tips - bases, axis=1)
        self.length_m = float(lengths[fingers].mean())
        self.digit_length_m: FloatArray = lengths
        self.bases: FloatArray = self.frame.local(bases)

    def tips(self, poses: FloatArray) -> FloatArray:
        """Poses (n, P) -> tips (n, digits, 3) in the palm frame, metres."""
        poses = np.atleast_2d(np.asarray(poses, dtype=np.float64))
        out = np.empty((len(poses), len(self.digits), 3))
        for i, p in enumerate(poses):
            self._set(p)
            mujoco.mj_kinematics(self.model, self.data)
            out[i] = self._tip_world()
        return self.frame.local(out)


class HumanTips(HandTips):
    """The human hand model (:func:`sim.hand_model.hand_model_xml`, right hand, wrist
    straight); a pose is the 50 curves in degrees (the right hand's are read)."""

    def __init__(self, digits: Sequence[str] = hand.DIGITS,
                 hand_length_m: float | None = None) -> None:
        geo = hand_geometry() if hand_length_m is None else hand_geometry(hand_length_m)
        super().__init__(mujoco.MjModel.from_xml_string(hand_model_xml("ri", geo.hand_length_m)),
                         digits)
        self._qidx = dof_qpos_indices(self.model, "ri")
        self._curve = hand.dof_curve_indices("ri")
        self._has_curve = self._curve >= 0
        self._tip_body = []
        self._tip_local = []
        self._base_body = []
        for d in self.digits:
            segs = geo.segments[d]
            self._tip_body.append(self._body(f"ri{d}{segs[-1].body}"))
            self._tip_local.append(np.array([segs[-1].length_m, 0.0, 0.0]))
            self._base_body.append(self._body(f"ri{d}{segs[0].body}"))
        self._straight(np.zeros(len(hand.CURVE_NAMES)))

    def _body(self, name: str) -> int:
        return int(mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, name))

    def _set(self, pose: FloatArray) -> None:
        q = np.zeros(len(self._qidx))
        q[self._has_curve] = np.radians(pose[self._curve[self._has_curve]])
        self.data.qpos[self._qidx] = q

    def _tip_world(self) -> FloatArray:
        d = self.data
        return np.array([d.xpos[b] + d.xmat[b].reshape(3, 3) @ p
                         for b, p in zip(self._tip_body, self._tip_local, strict=True)])

    def _bases_world(self) -> FloatArray:
        return np.array([self.data.xpos[b] for b in self._base_body])


class RobotTips(HandTips):
    """A robot hand's MJCF model; a pose is its joints in degrees, in ``joint_names``
    order (other joints stay at 0). ``chains``: per digit, its joints (any order)."""

    def __init__(self, model_path: str | Path, joint_names: Sequence[str],
                 chains: Mapping[str, Sequence[str]], fixed_deg: dict[str, float] | None = None
                 ) -> None:
        try:
            model = mujoco.MjModel.from_xml_path(str(model_path))
        except ValueError as exc:
            raise ConfigError(f"MuJoCo cannot load the robot model: {exc}",
                              file=str(model_path)) from None
        order = [d for d in hand.DIGITS if d in chains]
        super().__init__(model, order)
        self.joint_names = tuple(joint_names)
        self._qadr = np.array([self._joint(n, model_path)[1] for n in self.joint_names],
                              dtype=np.intp)
        self._fixed = {self._joint(n, model_path)[1]: np.radians(v)
                       for n, v in (fixed_deg or {}).items()}
        self._tip_body: list[int] = []
        self._tip_local: list[FloatArray] = []
        self._base_joint: list[int] = []
        for d in self.digits:
            ids = [self._joint(n, model_path)[0] for n in chains[d]]
            bodies = [int(model.jnt_bodyid[j]) for j in ids]
            depth = [self._depth(b) for b in bodies]
            self._tip_body.append(bodies[int(np.argmax(depth))])
            self._base_joint.append(ids[int(np.argmin(depth))])
        self._set(np.zeros(len(self.joint_names)))
        mujoco.mj_kinematics(self.model, self.data)
        bases = self._bases_world()
        for k, b in enumerate(self._tip_body):
            self._tip_local.append(self._far_corner(b, bases[k]))
        self._straight(np.zeros(len(self.joint_names)))

    def _joint(self, name: str, file: str | Path) -> tuple[int, int]:
        j = int(mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, name))
        if j < 0:
            raise ConfigError("no such joint in the robot model", file=str(file), value=name)
        return j, int(self.model.jnt_qposadr[j])

    def _depth(self, body: int) -> int:
        n = 0
        while body > 0:
            body = int(self.model.body_parentid[body])
            n += 1
        return n

    def _far_corner(self, body: int, base_world: FloatArray) -> FloatArray:
        """The corner of ``body``'s geom boxes farthest from ``base_world``, body frame."""
        m, d = self.model, self.data
        corners = []
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        for g in range(m.ngeom):
            if int(m.geom_bodyid[g]) != body:
                continue
            centre, half = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
            local = centre + signs * half  # geom frame
            world = d.geom_xpos[g] + local @ d.geom_xmat[g].reshape(3, 3).T
            corners.append(world)
        if not corners:
            return np.zeros(3)
        pts = np.concatenate(corners)
        far = pts[int(np.argmax(np.linalg.norm(pts - base_world, axis=1)))]
        out: FloatArray = d.xmat[body].reshape(3, 3).T @ (far - d.xpos[body])
        return out

    def _set(self, pose: FloatArray) -> None:
        self.data.qpos[:] = 0.0
        for adr, v in self._fixed.items():
            self.data.qpos[adr] = v
        self.data.qpos[self._qadr] = np.radians(pose)

    def _tip_world(self) -> FloatArray:
        d = self.data
        return np.array([d.xpos[b] + d.xmat[b].reshape(3, 3) @ p
                         for b, p in zip(self._tip_body, self._tip_local, strict=True)])

    def _bases_world(self) -> FloatArray:
        return np.array([self.data.xanchor[j] for j in self._base_joint])
