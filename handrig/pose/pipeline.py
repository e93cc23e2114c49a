"""The pose pipeline, pure numpy: controls -> full pose with sag -> servo targets.

Per loop cycle, :meth:`PosePipeline.servo_targets` (before the Sync Write) and
:meth:`PosePipeline.account` (after it) compute::

    control degrees (k,, calibrated and filtered upstream) --expand--> 50 curves
        + passive sag at the forearm orientation (23 DOFs per hand, wrist included)
        -> clamp to joint and servo limits -> slew limit -> the servos' joints (n,)

The full pose is a 54-vector laid out as :data:`handrig.hand.ALL_JOINT_NAMES`
(the 50 curves, then ``riWristFlexion, riWristDeviation, leWristFlexion,
leWristDeviation``), degrees in the vocabulary convention. Every array is
preallocated; :meth:`PosePipeline.servo_targets` allocates nothing.

A robot hand (``retarget`` given) drives the robot's joints instead: the servo
step computes the human curves the retarget table reads, clamps them to their joint
limits, then ``robot = clip(offset + G @ human50, robot range and servo limits)``
(:class:`RobotPath`), in the same one compiled call; outputs still get the human pose.

This module imports no device code (no serial port, no servo SDK, no mujoco).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.config.loading import JointLimits
from handrig.config.rig import LoopConfig
from handrig.errors import ConfigError
from handrig.pose import kernels
from handrig.pose.sag import SagGrid, SagTables

FloatArray = NDArray[np.float64]
POSE_NAMES: tuple[str, ...] = hand.ALL_JOINT_NAMES
POSE_SIZE = len(POSE_NAMES)
_POSE_INDEX = {n: i for i, n in enumerate(POSE_NAMES)}


def pose_index(name: str) -> int:
    """Index of a curve or wrist DOF in the 54-vector full pose."""
    try:
        return _POSE_INDEX[name]
    except KeyError:
        hand.curve(name)  # raises UnknownJointError with a suggestion
        raise


class MapLike(Protocol):
    @property
    def gains(self) -> FloatArray: ...  # (50, k)

    @property
    def curve_means_deg(self) -> FloatArray: ...  # (50,)

    @property
    def control_means_deg(self) -> FloatArray: ...  # (k,)

    def output_range_deg(self) -> FloatArray: ...  # (50, 2)

    def feature_gains(self) -> tuple[FloatArray, FloatArray, FloatArray]: ...
    # (50, k + h) gains on the features (controls, then hinges at the h knots), bias, knots


class ExpanderLike(Protocol):
    controls: tuple[str, ...]

    @property
    def map(self) -> MapLike: ...

    def expand(self, controls_deg: FloatArray, out: FloatArray | None = None) -> FloatArray: ...


class SagLike(Protocol):
    dof_names: Sequence[str]
    rest_deg: FloatArray

    def lookup(
        self, inclination_deg: float, rotation_deg: float, out: FloatArray | None = None
    ) -> FloatArray: ...

    def offsets(
        self, inclination_deg: float, rotation_deg: float, out: FloatArray | None = None
    ) -> FloatArray: ...

    def kernel_tables(self) -> SagTables: ...


SagSide = tuple[NDArray[np.intp], float, float, bool]
"""One hand's sag in the full pose: its pose indices, forearm inclination and rotation
(degrees), and whether it goes on the rest pose (else on the map's curves)."""


@dataclass(frozen=True)
class ServoPath:
    """The servo step precomposed (:meth:`PosePipeline.servo_targets`): the targets before
    limits are ``controls @ a + b + sag_gain * offsets[sag_slot]``, where ``offsets`` are
    the right hand's sag offsets at the forearm orientation, looked up in ``sag``, and a
    ``sag_slot`` of 23 (or more) means no sag for that servo. Read-only."""

    a: FloatArray  # (k controls, n servos)
    b: FloatArray  # (n,)
    sag_slot: NDArray[np.int64]  # (n,)
    sag_gain: float
    sag: SagTables
    map_low: FloatArray  # (n,) the map's output range, before sag (-inf/inf: none)
    map_high: FloatArray  # (n,)
    knots: FloatArray = field(default_factory=lambda: np.zeros(0))
    """(h,) a piecewise-linear map's knots: then ``a`` is over the features (the k
    controls, then ``max(0, controls[:h] - knots)``), which the servo step's kernel
    writes into a scratch buffer first."""


class RetargetLike(Protocol):
    """A compiled retarget table (:class:`handrig.pose.retarget.Retarget`)."""

    @property
    def joint_names(self) -> tuple[str, ...]: ...

    @property
    def gain(self) -> FloatArray: ...  # (J, 50)

    @property
    def offset_deg(self) -> FloatArray: ...  # (J,)

    @property
    def low_deg(self) -> FloatArray: ...  # (J,)

    @property
    def high_deg(self) -> FloatArray: ...  # (J,)


@dataclass(frozen=True)
class RobotPath:
    """A robot hand's servo step: ``human`` is the :class:`ServoPath` of the ``curves``
    (indices into the 50) that the retarget reads, clamped to ``[human_low, human_high]``;
    servo k's target is ``offset[k] + gain[k] @ that``. Rows in servo (bus) order.
    The kernel reads ``gain``'s nonzero entries row by row: row k's are
    ``gain_start[k]:gain_start[k + 1]`` of ``gain_curve`` (column) and ``gain_value``.
    ``full_gain`` (n, 50) is the same step over all 50 curves. Read-only."""

    human: ServoPath
    curves: NDArray[np.intp]  # (u,)
    human_low: FloatArray  # (u,)
    human_high: FloatArray  # (u,)
    gain: FloatArray  # (n, u)
    gain_start: NDArray[np.int64]  # (n + 1,)
    gain_curve: NDArray[np.int64]  # (nonzero,)
    gain_value: FloatArray  # (nonzero,)
    offset: FloatArray  # (n,)
    full_gain: FloatArray  # (n, 50)


class PosePipeline:
    """Turns control angles and a forearm orientation into servo joint targets.

    ``servo_joints`` names the joint each servo drives, in bus order;
    ``servo_limits_deg`` (n, 2) are the servos' own limits, intersected with the
    joint limits. ``left_hand``: ``"map"`` takes the left hand from the map,
    ``"mirror"`` copies the right hand's curves to the left (vocabulary values
    are hand-independent), ``"relaxed"`` holds the left hand at its relaxed pose.
    ``left_forearm_deg`` (inclination, rotation) is where the left forearm is
    taken to be for its sag (default: hanging at rest).

    ``glove_hand``: the hand whose forearm the orientation given to each step is
    (``"ri"``, the one-glove rig; ``"le"``: the left hand's loop of a two-glove rig,
    whose servos drive left-hand joints); the other forearm is taken to be at
    :attr:`other_forearm_deg` (``left_forearm_deg`` for the left, ``right_forearm_deg``
    for the right), which a two-hand run updates from the other glove.

    ``retarget``: a robot hand; ``servo_joints`` then name the robot's joints (rows of
    the table, in bus order) and the servo limits are intersected with the table's
    ranges instead of the human joint limits.
    """

    def __init__(
        self,
        expander: ExpanderLike,
        sag: SagLike | None,
        servo_joints: Sequence[str],
        *,
        servo_limits_deg: FloatArray | None = None,
        limits: JointLimits | None = None,
        slew_deg_s: float = LoopConfig.slew_deg_s,
        sag_gain: float = 1.0,
        left_hand: Literal["map", "mirror", "relaxed"] = "map",
        control_means_deg: FloatArray | None = None,
        left_forearm_deg: tuple[float, float] = (-90.0, 0.0),
        retarget: RetargetLike | None = None,
        glove_hand: Literal["ri", "le"] = "ri",
        right_forearm_deg: tuple[float, float] = (-90.0, 0.0),
    ) -> None:
        self.expander = expander
        self.sag = sag
        self.servo_joints = tuple(servo_joints)
        self.slew_deg_s = float(slew_deg_s)
        self.sag_gain = float(sag_gain)
        self.left_hand = left_hand
        if glove_hand not in ("ri", "le"):
            raise ConfigError("unknown glove hand", key="glove_hand", value=glove_hand,
                              allowed="ri or le")
        if glove_hand == "le" and (left_hand != "map" or retarget is not None):
            raise ConfigError("a left-hand glove needs the left hand from the map",
                              key="loop.left_hand", value=left_hand,
                              allowed='"map" (and a human rig) with a glove per hand')
        self.glove_hand = glove_hand
        self.left_forearm_deg = left_forearm_deg
        self.other_forearm_deg = (left_forearm_deg if glove_hand == "ri"
                                  else right_forearm_deg)
        """Where the forearm without this pipeline's glove is (inclination, rotation):
        its sag in :meth:`full_pose` and :meth:`relaxed_pose`."""
        self.retarget = retarget
        limits = limits or JointLimits()
        n = len(self.servo_joints)
        lim = np.array([limits.of(name) for name in POSE_NAMES], dtype=np.float64)
        self.pose_low, self.pose_high = lim[:, 0].copy(), lim[:, 1].copy()
        if retarget is None:
            self.servo_index = np.array([pose_index(j) for j in self.servo_joints],
                                        dtype=np.intp)
            self.servo_low = self.pose_low[self.servo_index].copy()
            self.servo_high = self.pose_high[self.servo_index].copy()
        else:
            self.servo_index = np.zeros(0, dtype=np.intp)  # robot joints are not pose DOFs
            self._robot_rows = np.array([_robot_row(retarget, j) for j in self.servo_joints],
                                        dtype=np.intp)
            self.servo_low = np.asarray(retarget.low_deg, dtype=np.float64)[self._robot_rows]
            self.servo_high = np.asarray(retarget.high_deg, dtype=np.float64)[self._robot_rows]
        if servo_limits_deg is not None:
            sl = np.asarray(servo_limits_deg, dtype=np.float64)
            if sl.shape != (n, 2):
                raise ConfigError(f"servo limits must be ({n}, 2), got {sl.shape}")
            self.servo_low = np.maximum(self.servo_low, sl[:, 0])
            self.servo_high = np.minimum(self.servo_high, sl[:, 1])
        if np.any(self.servo_low >= self.servo_high):
            bad = self.servo_joints[int(np.argmax(self.servo_low >= self.servo_high))]
            raise ConfigError(f"servo limits of {bad} do not overlap its joint limits")
        # Where each hand's 23 sag DOFs live in the full pose.
        self.sag_index: dict[str, NDArray[np.intp]] = {}
        if sag is not None:
            names = list(sag.dof_names)
            if len(names) != hand.DOFS_PER_HAND:
                raise ConfigError(f"sag grid has {len(names)} DOFs, expected 23")
            for h in hand.HANDS:
                mapped = [h + name[2:] for name in names]
                self.sag_index[h] = np.array([pose_index(m) for m in mapped], dtype=np.intp)
        # One grid view per hand, made once (views rename the DOFs; values are shared).
        self._grids: dict[str, SagLike] = {}
        if sag is not None:
            view = getattr(sag, "for_hand", None)
            for h in hand.HANDS:
                self._grids[h] = view(h) if callable(view) else sag
        self._has_sag = "ri" in self._grids
        k = len(expander.controls)
        self.control_means_deg = (
            np.zeros(k) if control_means_deg is None
            else np.asarray(control_means_deg, dtype=np.float64).copy()
        )
        self.clamps = 0  # pose values (all 54) clamped to joint limits, cumulative
        self.servo_clamps = 0  # servo targets that needed clamping, cumulative
        # the same per servo (servo_joints order)
        self.servo_clamps_by_servo = np.zeros(len(self.servo_joints), dtype=np.int64)
        self.slewed = 0  # servo targets held back by the slew limit, cumulative
        self.rejected = 0  # non-finite targets replaced by the last good one, cumulative
        self._has_targets = False
        self._allocate_work()
        self.robot_path: RobotPath | None = None
        if retarget is None:
            self.servo_path = self._build_servo_path(self.servo_joints)
        else:
            self.robot_path = self._build_robot_path(retarget)
            self.servo_path = self.robot_path.human
            self._human = np.zeros(len(self.robot_path.curves))
        # :meth:`rehearse`'s own targets, features, raw targets and robot curves
        self._rehearsal = (np.zeros_like(self.targets), np.zeros_like(self._features),
                           np.zeros_like(self._raw_targets), np.zeros_like(self._human))
        grid = self._grids.get("ri")
        self._sag_tables = grid.kernel_tables() if grid is not None else SagTables.empty()
        self._sag_rest = (np.asarray(grid.rest_deg, dtype=np.float64) if grid is not None
                          else np.zeros(hand.DOFS_PER_HAND))
        robot = self.robot_path
        self._full_gain = robot.full_gain if robot is not None else np.zeros((0, 50))
        self._offset = robot.offset if robot is not None else np.zeros(0)
        kernels.warm_up()

    def _allocate_work(self) -> None:
        """The arrays a step writes (all of them)."""
        n = len(self.servo_joints)
        self.curves = np.zeros(hand.CURVES_PER_HAND * 2)
        self.pose = np.zeros(POSE_SIZE)
        self.relaxed = np.zeros(POSE_SIZE)
        self.targets = np.zeros(n)
        self._relaxed_targets = np.zeros(n)
        self._sag_values = np.zeros(hand.DOFS_PER_HAND)
        self._sag_offsets = np.zeros(hand.DOFS_PER_HAND)
        self._clamped_pose = np.zeros(POSE_SIZE)
        self._raw_targets = np.zeros(n)
        self._step = np.zeros(n)
        self._human = np.zeros(0)  # a robot rig's human curves (its retarget's input)
        _, _, knots = self.expander.map.feature_gains()  # the servo step's scratch
        self._features = np.zeros(len(self.expander.controls) + len(knots))

    def _build_robot_path(self, rt: RetargetLike) -> RobotPath:
        """The retarget rows in servo order over the curves they read (a curve is read
        when some row has a nonzero gain on it), and the human path of those curves. Sag
        on them only with a nonzero ``sag_gain``."""
        full = np.ascontiguousarray(np.asarray(rt.gain, dtype=np.float64)[self._robot_rows])
        if full.shape[1] != hand.CURVES_PER_HAND * 2:
            raise ConfigError(f"a retarget table reads the 50 curves, got {full.shape[1]}")
        curves = np.flatnonzero(np.any(full != 0.0, axis=0)).astype(np.intp)
        human = self._build_servo_path([POSE_NAMES[c] for c in curves])
        if self.sag_gain == 0.0:
            human = ServoPath(human.a, human.b, human.sag_slot, 0.0, SagTables.empty(),
                              human.map_low, human.map_high, human.knots)
        offset = np.asarray(rt.offset_deg, dtype=np.float64)[self._robot_rows].copy()
        gain = np.ascontiguousarray(full[:, curves])
        rows, cols = np.nonzero(gain)  # row-major order
        start = np.searchsorted(rows, np.arange(len(gain) + 1)).astype(np.int64)
        return RobotPath(human, curves, self.pose_low[curves].copy(),
                         self.pose_high[curves].copy(), gain, start, cols.astype(np.int64),
                         np.ascontiguousarray(gain[rows, cols]), offset, full)

    def _build_servo_path(self, joints: Sequence[str]) -> ServoPath:
        """Precompose the servo joints' targets as one affine map of the controls, plus the
        right forearm's sag offsets (the left forearm's are constant: no IMU there).

        ``targets = clip(controls @ A + b, map_low, map_high) + gain * offsets[sag_slot]``
        (the map's output range, as the expander clips) then one clamp to the joint and
        servo limits. The expander clamps each curve before sag is added; this
        path clamps once after, which differs only where a curve leaves its limits and
        sag brings it back: the end result is inside the limits either way.
        """
        m = self.expander.map
        gains, bias, knots = m.feature_gains()
        n, k = len(joints), gains.shape[1]
        a = np.zeros((k, n))
        b = np.zeros(n)
        rng = np.asarray(m.output_range_deg(), dtype=np.float64)
        map_low = np.full(n, -np.inf)
        map_high = np.full(n, np.inf)
        slot = np.full(n, hand.DOFS_PER_HAND, dtype=np.int64)  # index 23 = no sag
        live = self.glove_hand  # the hand whose sag follows the glove's forearm
        other: str = "le" if live == "ri" else "ri"
        left_const = np.zeros(hand.DOFS_PER_HAND)  # the other hand's constant sag
        left_rest = np.zeros(hand.DOFS_PER_HAND)
        left_grid = self._grids.get(other)
        if left_grid is not None and self.left_hand != "mirror":
            left_grid.offsets(*self.other_forearm_deg, out=left_const)
            left_rest[:] = left_grid.rest_deg
        for j, name in enumerate(joints):
            i = pose_index(name)
            h = hand.hand_of(name)
            if i < 50:
                src = i
                if h == "le" and self.left_hand == "mirror":
                    src = hand.curve_index(hand.mirror_name(name))
                if not (h == "le" and self.left_hand == "relaxed"):
                    a[:, j] = gains[src]
                    b[j] = bias[src]
                    map_low[j], map_high[j] = rng[src]
            if h not in self.sag_index:
                continue
            hits = np.flatnonzero(self.sag_index[h] == i)
            if not len(hits):
                continue  # finger twist: no DOF in the relaxed-hand model
            d = int(hits[0])
            if h == live or self.left_hand == "mirror":
                slot[j] = d
            else:
                b[j] += self.sag_gain * left_const[d]
                if self.left_hand == "relaxed":
                    b[j] += left_rest[d]
        grid = self._grids.get(live)
        tables = grid.kernel_tables() if grid is not None else SagTables.empty()
        return ServoPath(np.ascontiguousarray(a), b, slot, self.sag_gain, tables, map_low,
                         map_high, np.ascontiguousarray(knots, dtype=np.float64))

    # -- pieces ---------------------------------------------------------------------------
    def _add_sag(self, pose: FloatArray, h: str, inclination_deg: float,
                 rotation_deg: float, *, absolute: bool) -> None:
        grid = self._grids.get(h)
        if grid is None:
            return
        grid.lookup(inclination_deg, rotation_deg, out=self._sag_values)
        np.subtract(self._sag_values, grid.rest_deg, out=self._sag_offsets)
        self._sag_offsets *= self.sag_gain
        idx = self.sag_index[h]
        if absolute:
            pose[idx] = grid.rest_deg
        pose[idx] += self._sag_offsets

    def full_pose(
        self, controls_deg: FloatArray, inclination_deg: float, rotation_deg: float
    ) -> FloatArray:
        """The 54-vector pose (the map's active pose plus passive sag), not yet clamped.

        The glove's forearm orientation gives the right hand's sag; the left forearm
        has no IMU, so the left hand sags as at ``left_forearm_deg``. One compiled pass
        after the map (:func:`handrig.pose.kernels.pose_from_curves`).
        """
        self.expander.expand(controls_deg, out=self.curves)
        (ia, inc_a, rot_a, abs_a), (ib, inc_b, rot_b, abs_b) = self._sag_sides(
            inclination_deg, rotation_deg)
        t = self._sag_tables
        kernels.pose_from_curves(
            self.curves, self.left_hand == "mirror", self.pose, ia, inc_a, rot_a, abs_a,
            ib, inc_b, rot_b, abs_b, t.inclination_axis_deg, t.rotation_axis_deg,
            t.rotation0_deg, t.cell_offsets_deg, self._sag_rest, self.sag_gain)
        return self.pose

    def _sag_sides(self, inclination_deg: float, rotation_deg: float
                   ) -> tuple[SagSide, SagSide]:
        """The two hands' sag in the full pose: (pose indices, inclination, rotation, on
        the rest pose) for the glove's hand, then the other, whose forearm is
        ``other_forearm_deg`` (the glove's with a mirrored left hand), on the rest pose
        for a relaxed left hand. Checked as a grid lookup checks them (DataError for NaN)."""
        if not self._has_sag:
            none = np.zeros(0, dtype=np.intp)
            return (none, 0.0, 0.0, False), (none, 0.0, 0.0, False)
        live, other = ("le", "ri") if self.glove_hand == "le" else ("ri", "le")
        inc_b, rot_b = ((inclination_deg, rotation_deg)
                        if self.left_hand == "mirror" and live == "ri"
                        else self.other_forearm_deg)
        absolute = live == "ri" and self.left_hand == "relaxed"
        return ((self.sag_index[live],
                 SagGrid.checked_inclination(inclination_deg, rotation_deg),
                 float(rotation_deg), False),
                (self.sag_index[other], SagGrid.checked_inclination(inc_b, rot_b), float(rot_b),
                 absolute))

    def relaxed_pose(self, inclination_deg: float, rotation_deg: float) -> FloatArray:
        """The relaxed hands at this orientation: the passive model's pose for every DOF,
        the map's value at the mean controls for curves the model lacks (finger twist)."""
        self.expander.expand(self.control_means_deg, out=self.curves)
        self.relaxed[:50] = self.curves
        self.relaxed[50:] = 0.0
        live, other = ("le", "ri") if self.glove_hand == "le" else ("ri", "le")
        self._add_sag(self.relaxed, live, inclination_deg, rotation_deg, absolute=True)
        self._add_sag(self.relaxed, other, *self.other_forearm_deg, absolute=True)
        return self.relaxed

    # -- the per-cycle step ----------------------------------------------------------------
    def servo_targets(
        self, controls_deg: FloatArray, inclination_deg: float, rotation_deg: float, dt_s: float
    ) -> FloatArray:
        """The servo targets only (degrees, bus order): the short path the loop runs
        between reading a glove frame and handing the Sync Write to the OS, one call of
        the compiled step (:func:`handrig.pose.kernels.servo_targets`) on :attr:`servo_path`.
        A non-finite target holds the previous one (counted in ``rejected``); targets
        move at most ``slew_deg_s * dt_s`` from the previous ones. Call :meth:`account`
        afterwards for the full pose (outputs) and the statistics."""
        if self._has_sag:
            inclination_deg = SagGrid.checked_inclination(inclination_deg, rotation_deg)
        self.rejected += self._step_into(
            controls_deg, inclination_deg, rotation_deg, self.slew_deg_s * max(dt_s, 0.0),
            not self._has_targets, self.targets, self._features, self._raw_targets, self._human)
        self._has_targets = True
        return self.targets

    def rehearse(self, controls_deg: FloatArray, inclination_deg: float,
                 rotation_deg: float) -> FloatArray:
        """:meth:`servo_targets`' compiled step once into scratch arrays (the loop's
        warm-up before an expected glove frame: its code and tables are then in the CPU's
        caches): the targets, the slew limit's memory and the counters stay as they were.
        Returns the scratch targets (for the bus's own rehearsal)."""
        scratch = self._rehearsal
        scratch[0][:] = self.targets  # the slew limit starts from the targets sent
        if not (-90.0 <= inclination_deg <= 90.0 and math.isfinite(rotation_deg)):
            inclination_deg = rotation_deg = 0.0  # what the real step would refuse
        self._step_into(controls_deg, inclination_deg, rotation_deg, 0.0,
                        not self._has_targets, *scratch)
        return scratch[0]

    def _step_into(self, controls_deg: FloatArray, inclination_deg: float, rotation_deg: float,
                   max_step_deg: float, first: bool, targets: FloatArray, features: FloatArray,
                   raw_targets: FloatArray, human: FloatArray) -> int:
        """The compiled step on the arrays given; returns the targets it rejected."""
        path = self.servo_path
        tables = path.sag
        robot = self.robot_path
        controls = np.ascontiguousarray(controls_deg, dtype=np.float64)
        if robot is not None:
            return int(kernels.robot_servo_targets(
                controls, path.knots, features, path.a, path.b,
                tables.inclination_axis_deg, tables.rotation_axis_deg, tables.rotation0_deg,
                tables.cell_offsets_deg, path.sag_slot, float(path.sag_gain),
                path.map_low, path.map_high,
                float(inclination_deg), float(rotation_deg), robot.human_low,
                robot.human_high, human, robot.gain_start, robot.gain_curve,
                robot.gain_value, robot.offset, self.servo_low,
                self.servo_high, targets, float(max_step_deg), first, raw_targets))
        return int(kernels.servo_targets(
            controls, path.knots, features, path.a, path.b,
            tables.inclination_axis_deg, tables.rotation_axis_deg, tables.rotation0_deg,
            tables.cell_offsets_deg, path.sag_slot, float(path.sag_gain),
            path.map_low, path.map_high,
            float(inclination_deg), float(rotation_deg), self.servo_low, self.servo_high,
            targets, float(max_step_deg), first, raw_targets))

    @property
    def raw_targets(self) -> FloatArray:
        """The last step's targets before the slew limit (clamped to the limits)."""
        return self._raw_targets

    def relaxed_targets(self, inclination_deg: float, rotation_deg: float) -> FloatArray:
        """The servo targets of the relaxed hands at this orientation, clamped to the
        joint and servo limits; :attr:`relaxed` then holds the clamped full pose."""
        relaxed = self.relaxed_pose(inclination_deg, rotation_deg)
        np.clip(relaxed, self.pose_low, self.pose_high, out=relaxed)
        self._servo_values(relaxed, self._relaxed_targets)
        np.clip(self._relaxed_targets, self.servo_low, self.servo_high,
                out=self._relaxed_targets)
        return self._relaxed_targets

    def account(
        self, controls_deg: FloatArray, inclination_deg: float, rotation_deg: float, *,
        slewed: bool = True,
    ) -> FloatArray:
        """After the write: the full 54-vector pose, clamped (for outputs), and the
        clamp and slew counters for this cycle (``slewed=False``: the slew counter was
        counted already, :meth:`count_slewed`, and the targets are another cycle's).

        :meth:`full_pose`, then its clamp and the counters in one compiled pass
        (:func:`handrig.pose.kernels.account_pose`): a robot's joints are retargeted
        from the clamped curves, a human rig's servos take the pose as it is."""
        pose = self.full_pose(controls_deg, inclination_deg, rotation_deg)
        clamps, servo_clamps, slew = kernels.account_pose(
            pose, self.pose_low, self.pose_high, self._clamped_pose, self.robot_path is not None,
            self._full_gain, self._offset, self.servo_index, self.servo_low, self.servo_high,
            self._step, self.servo_clamps_by_servo, self._raw_targets, self.targets, slewed)
        self.clamps += clamps
        self.servo_clamps += servo_clamps
        self.slewed += slew
        return pose

    def count_slewed(self) -> None:
        """Count the servo targets the slew limit held back in the last step."""
        self.slewed += int(np.count_nonzero(np.abs(self._raw_targets - self.targets) > 1e-9))

    def _servo_values(self, pose: FloatArray, out: FloatArray) -> None:
        """The servos' joint values (unclamped) of a 54-vector pose, into ``out``: the
        pose's own values, or a robot's retargeted joints."""
        robot = self.robot_path
        if robot is None:
            np.take(pose, self.servo_index, out=out)
            return
        np.dot(robot.full_gain, pose[:50], out=out)
        out += robot.offset

    @property
    def has_targets(self) -> bool:
        """Whether slew limiting has a starting point (a step or :meth:`seed` ran)."""
        return self._has_targets

    def seed(self, targets_deg: FloatArray) -> None:
        """Start slew limiting from where the servos are (e.g. their present positions)."""
        self.targets[:] = np.clip(targets_deg, self.servo_low, self.servo_high)
        self._has_targets = True


def _robot_row(rt: RetargetLike, joint: str) -> int:
    """Row of robot joint ``joint`` in the retarget table; ConfigError when it has none."""
    try:
        return rt.joint_names.index(joint)
    except ValueError:
        raise ConfigError(f"the retarget table has no row for servo joint {joint!r}",
                          key=f"joints.{joint}",
                          allowed=f"one of {', '.join(rt.joint_names)}") from None
