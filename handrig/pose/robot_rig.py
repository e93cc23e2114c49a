"""Robot-hand rig files: servos that drive the joints of a robot's MJCF model.

A robot rig is a rig file (see :mod:`handrig.config.rig`) with a ``[robot]`` table::

    [robot]
    name = "LEAP hand (right)"
    model = "../../data/robots/leap_hand/right_hand.xml"  # MJCF, relative to this file
    retarget = "leap_retarget.toml"                        # human curves -> robot joints
    sag = false                                            # passive sag off unless true
    gravity = true                 # goals offset against the fingers' weight (optional)
    gravity_direction = [0, 0, -1] # gravity in the model's frame: how the hand is mounted

and ``[[servos]]`` whose ``joint`` is a joint of that model (``if_mcp``), its angle
in degrees as the model measures it, instead of a human curve. Loading checks what
a rig file is checked for, and also that every servo's joint is a hinge of the
model within whose range the servo's limits lie, that the retarget table agrees
with the model, and that every servo's joint has a row in the table. Paths in
the loaded config are absolute.

Presets live in ``config/rigs/``: ``load_rig("leap")`` is ``config/rigs/leap.toml``
(:mod:`handrig.config.rig_files` says which file a name means).
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from pathlib import Path

from handrig.config.loading import load, load_toml
from handrig.config.rig import RigConfig, ServoCalibration, hand_of_joint, load_rig_config
from handrig.config.rig_files import rig_file_path
from handrig.errors import ConfigError
from handrig.hand import is_joint_name
from handrig.pose.mjcf import MjcfJoint, read_joints
from handrig.pose.retarget import Retarget, load_retarget

_JOINT_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")
STANDARD_GRAVITY_MPS2 = 9.80665
RANGE_TOLERANCE_DEG = 0.05  # servo limits may round the model's range by this much


@dataclass(frozen=True)
class RobotConfig:
    """``[robot]``: the model the servos drive and the retarget table that feeds them."""

    model: str
    retarget: str
    name: str = ""
    sag: bool = False  # robot servos hold position: no passive sag unless switched on
    render_view: tuple[float, ...] = ()
    """Where ``--render`` looks from: distance (m), azimuth and elevation (degrees)
    around the hand; empty: the default view (each robot's palm faces another way)."""
    gravity: bool = False
    """Offset each servo's goal by the torque gravity puts on its joint at that goal
    over the servo's stiffness (:mod:`handrig.pose.gravity`), so fingers reach their
    goals instead of sagging short of them."""
    gravity_direction: tuple[float, ...] = (0.0, 0.0, -1.0)
    """Which way gravity points in the model's own frame (the MJCF's world): how the
    hand is fixed on its table. The default is the model as it is drawn, its z up."""
    gravity_from: str = "table"
    """``"table"``: gravity along :attr:`gravity_direction`, fixed; ``"forearm"``: the
    hand is mounted on an arm that follows the glove's forearm, and gravity follows the
    forearm IMU's inclination and rotation each cycle through :attr:`forearm_axes`."""
    forearm_axes: tuple[tuple[float, ...], ...] = ()
    """With ``gravity_from = "forearm"``: the forearm frame's x (distal) and z (dorsal,
    the back of the hand) axes as seen in the model's frame, ``[[x], [z]]``."""

    def check(self) -> None:
        for key in ("model", "retarget"):
            if not getattr(self, key):
                raise ConfigError("must name a file", key=key)
        view = tuple(self.render_view)
        if view and (len(view) != 3 or not 0.05 <= float(view[0]) <= 5.0
                     or not -90.0 <= float(view[2]) <= 90.0):
            raise ConfigError("not a camera view", key="render_view", value=list(view),
                              allowed="[distance m (0.05..5), azimuth deg, elevation deg "
                              "(-90..90)], e.g. [0.40, 30.0, -35.0]")
        down = tuple(float(x) for x in self.gravity_direction)
        if len(down) != 3 or not all(math.isfinite(x) for x in down) or math.hypot(
                *down) < 1e-6:
            raise ConfigError("not a direction", key="gravity_direction",
                              value=list(self.gravity_direction),
                              allowed="3 numbers, not all 0: which way gravity points in "
                              "the model's frame, e.g. [0, 0, -1] (the model as drawn)")
        self._check_forearm()

    def _check_forearm(self) -> None:
        if self.gravity_from not in ("table", "forearm"):
            raise ConfigError("unknown gravity source", key="gravity_from",
                              value=self.gravity_from, allowed='"table" or "forearm"')
        if self.gravity_from == "table" and not self.forearm_axes:
            return
        allowed = ("[[x], [z]]: the forearm's distal (x) and dorsal (z) axes in the "
                   "model's frame, unit and at right angles, e.g. [[1, 0, 0], [0, 0, -1]]")
        rows = [tuple(float(v) for v in row) for row in self.forearm_axes]
        if len(rows) != 2 or any(len(r) != 3 or not all(math.isfinite(v) for v in r)
                                 for r in rows):
            raise ConfigError("needs two axes of 3 numbers", key="forearm_axes",
                              value=[list(r) for r in rows], allowed=allowed)
        x, z = rows
        nx, nz = math.hypot(*x), math.hypot(*z)
        if abs(nx - 1.0) > 1e-3 or abs(nz - 1.0) > 1e-3 or abs(
                sum(a * b for a, b in zip(x, z, strict=True))) > 1e-3:
            raise ConfigError("not two unit axes at right angles", key="forearm_axes",
                              value=[list(r) for r in rows], allowed=allowed)

    @property
    def forearm_to_model(self) -> tuple[tuple[float, float, float], ...]:
        """The 3x3 rotation (rows) taking forearm-frame vectors into the model's frame:
        its columns are the forearm's x, y = z cross x and z axes (:attr:`forearm_axes`)."""
        x = [float(v) for v in self.forearm_axes[0]]
        z = [float(v) for v in self.forearm_axes[1]]
        y = [z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0]]
        return tuple((x[i], y[i], z[i]) for i in range(3))

    @property
    def gravity_mps2(self) -> tuple[float, float, float]:
        """Gravity in the model's frame (m/s^2): :attr:`gravity_direction` scaled to g."""
        x, y, z = (float(v) for v in self.gravity_direction)
        norm = math.hypot(x, y, z)
        g = STANDARD_GRAVITY_MPS2 / norm
        return x * g, y * g, z * g


@dataclass(frozen=True)
class RobotServoCalibration(ServoCalibration):
    """A servo of a robot rig: ``joint`` is a joint of the robot's model, degrees as the
    model measures them. Same calibration as :class:`ServoCalibration` (the driver
    checks its zero and limits against the servo's position range)."""

    def check(self) -> None:
        if self.id < 0:
            raise ConfigError("servo ID out of range", key="id", value=self.id,
                              allowed="0 or more (and at most the bus's own maximum)")
        if not _JOINT_NAME.match(self.joint):
            raise ConfigError("not a joint name", key="joint", value=self.joint,
                              allowed="a joint of the robot's MJCF model, e.g. if_mcp")
        if is_joint_name(self.joint):
            raise ConfigError(
                "a human curve in a robot rig", key="joint", value=self.joint,
                allowed="a joint of the robot's model; human curves reach it through "
                "[robot].retarget",
            )
        if not 0.1 <= self.gear_ratio <= 20.0:
            raise ConfigError("implausible gear ratio", key="gear_ratio", value=self.gear_ratio,
                              allowed="0.1..20 servo turns per joint turn")
        if self.min_deg >= self.max_deg:
            raise ConfigError("inverted limit: min_deg must be below max_deg", key="min_deg",
                              value=[self.min_deg, self.max_deg], allowed="min_deg < max_deg")


@dataclass(frozen=True)
class RobotRigConfig(RigConfig):
    """A rig file with ``[robot]``: servos drive a robot model's joints."""

    servos: tuple[RobotServoCalibration, ...] = ()
    robot: RobotConfig | None = None

    @property
    def effective_sag_gain(self) -> float:
        """The sag gain the pipeline uses: 0 unless ``[robot].sag`` is true."""
        return self.loop.sag_gain if self.robot is not None and self.robot.sag else 0.0


def find_rig(name_or_path: str | Path | None) -> tuple[Path, RigConfig]:
    """The rig file a run loads for ``--rig`` (:func:`handrig.config.rig_files.
    resolve_rig_file`: a preset, a path, else your ``rig.toml``, else the shipped one)
    and its config."""
    path = rig_file_path(name_or_path)
    return path, load_rig(path)


def is_two_hand(rig: RigConfig) -> bool:
    """Whether ``rig`` drives servos of both hands (a robot rig never does)."""
    hands = {hand_of_joint(s.joint) for s in rig.servos}
    return hands == {"ri", "le"} and not isinstance(rig, RobotRigConfig)


def load_rig(name_or_path: str | Path | None = None) -> RigConfig:
    """Load a rig file or preset (None: the default, as :func:`find_rig`): a
    :class:`RobotRigConfig` when it has ``[robot]``, else the human rig of
    :func:`handrig.config.rig.load_rig_config`."""
    path = rig_file_path(name_or_path)
    if "robot" not in load_toml(path):
        return load_rig_config(path)
    return load_robot_rig(path)


def load_robot_rig(path: str | Path) -> RobotRigConfig:
    """Load and cross-check a robot rig file (model, retarget table, servos)."""
    p = Path(path)
    rig = load(p, RobotRigConfig)
    if rig.robot is None:
        raise ConfigError("missing table [robot]", file=str(p),
                          allowed="[robot] with model and retarget")
    base = p.resolve().parent
    robot = dataclasses.replace(
        rig.robot, model=str((base / rig.robot.model).resolve()),
        retarget=str((base / rig.robot.retarget).resolve()),
    )
    rig = dataclasses.replace(rig, robot=robot)
    joints = read_joints(robot.model)
    check_servos_against_model(rig, joints, file=str(p))
    table = load_retarget(robot.retarget)
    table.check_against_model(joints, file=robot.retarget)
    check_servos_against_retarget(rig, table, file=str(p))
    return rig


def robot_retarget(rig: RobotRigConfig) -> Retarget:
    """The compiled retarget table of a loaded robot rig."""
    if rig.robot is None:
        raise ConfigError("not a robot rig (no [robot] table)")
    return load_retarget(rig.robot.retarget)


def check_servos_against_model(rig: RigConfig, joints: dict[str, MjcfJoint], *,
                               file: str) -> None:
    """Each servo drives a hinge of the model, within its range."""
    for i, s in enumerate(rig.servos):
        j = joints.get(s.joint)
        if j is None or j.type != "hinge":
            import difflib

            close = difflib.get_close_matches(s.joint, list(joints), n=1)
            hint = f"did you mean {close[0]!r}? " if close else ""
            raise ConfigError("no such hinge joint in the robot model", file=file,
                              key=f"servos[{i}].joint", value=s.joint,
                              allowed=f"{hint}one of {', '.join(joints)}")
        if j.range is not None:
            low, high = j.range
            tol = RANGE_TOLERANCE_DEG
            for key, bad in (("min_deg", s.min_deg < low - tol),
                             ("max_deg", s.max_deg > high + tol)):
                if bad:
                    raise ConfigError(
                        f"servo limit exceeds the model's range of {s.joint}", file=file,
                        key=f"servos[{i}].{key}", value=getattr(s, key),
                        allowed=f"within [{low:.2f}, {high:.2f}] deg",
                    )


def check_servos_against_retarget(rig: RigConfig, table: Retarget, *, file: str) -> None:
    """Every servo's joint has a row in the retarget table."""
    for i, s in enumerate(rig.servos):
        if s.joint not in table.joint_names:
            raise ConfigError("the retarget table has no row for this joint", file=file,
                              key=f"servos[{i}].joint", value=s.joint,
                              allowed=f"add [joints.{s.joint}] to the retarget table")


def render_view(rig: RigConfig) -> tuple[float, float, float] | None:
    """A robot rig's ``[robot].render_view`` (distance, azimuth, elevation); None: the
    renderer's default."""
    if isinstance(rig, RobotRigConfig) and rig.robot and rig.robot.render_view:
        d, a, e = (float(x) for x in rig.robot.render_view)
        return d, a, e
    return None
