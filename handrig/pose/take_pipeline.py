"""A recorded performance as the loop's pose source: :class:`TakePipeline`.

``handrig play TAKE --bus`` plays a performance (the full pose per frame, recorded by
``handrig run --record`` or captured) onto the servos through the live loop. The
loop's "controls" are then the take's 54 pose values (:data:`POSE_NAMES` order): the
servo step picks each servo's joint out of them (a robot hand: retargets the curves),
clamps to the joint and servo limits and applies the slew limit, as for a glove. The
take already holds its sag, so the step adds none; the relaxed pose (a lost frame, a
stop, the relax key) is the live rig's: the map at its mean controls with the passive
model's sag at the forearm angles the loop is given.

Pure numpy: no device code.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from handrig import hand
from handrig.pose.pipeline import POSE_NAMES, POSE_SIZE, FloatArray, PosePipeline, ServoPath
from handrig.pose.sag import SagTables

_CURVES = hand.CURVES_PER_HAND * 2


class PoseMap:
    """The identity map over a full pose (the MapLike a :class:`PoseExpander` shows):
    curve i is control i. ``rest_curves_deg`` (50,) is what "the mean controls" expand to:
    the live map's relaxed curves."""

    def __init__(self, rest_curves_deg: FloatArray) -> None:
        rest = np.asarray(rest_curves_deg, dtype=np.float64)
        if rest.shape != (_CURVES,):
            raise ValueError(f"rest curves must be ({_CURVES},), got {rest.shape}")
        self._gains = np.eye(_CURVES, POSE_SIZE)
        self._curve_means = rest.copy()
        self._control_means = np.concatenate([rest, np.zeros(POSE_SIZE - _CURVES)])

    @property
    def gains(self) -> FloatArray:
        return self._gains

    @property
    def curve_means_deg(self) -> FloatArray:
        return self._curve_means

    @property
    def control_means_deg(self) -> FloatArray:
        return self._control_means

    def output_range_deg(self) -> FloatArray:
        return np.tile([-np.inf, np.inf], (_CURVES, 1))

    def feature_gains(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        return (self._gains.copy(), self._curve_means - self._gains @ self._control_means,
                np.zeros(0))


class PoseExpander:
    """The ExpanderLike of a take: the controls are the full pose's 54 values."""

    controls: tuple[str, ...] = POSE_NAMES

    def __init__(self, rest_curves_deg: FloatArray) -> None:
        self._map = PoseMap(rest_curves_deg)

    @property
    def map(self) -> PoseMap:
        return self._map

    @property
    def control_means_deg(self) -> FloatArray:
        return self._map.control_means_deg

    def expand(self, controls_deg: FloatArray, out: FloatArray | None = None) -> FloatArray:
        if out is None:
            out = np.empty(_CURVES)
        out[:] = controls_deg[:_CURVES]
        return out


class TakePipeline(PosePipeline):
    """:class:`PosePipeline` whose controls are a recorded full pose (module docstring).
    Build it with a :class:`PoseExpander` and the live pipeline's settings."""

    def _build_servo_path(self, joints: Sequence[str]) -> ServoPath:
        """Each servo's joint picked out of the pose (wrist DOFs included); no sag, no
        map range: the take holds its own, and the limits clamp after."""
        n = len(joints)
        a = np.zeros((POSE_SIZE, n))
        for j, name in enumerate(joints):
            a[POSE_NAMES.index(name), j] = 1.0
        return ServoPath(np.ascontiguousarray(a), np.zeros(n),
                         np.full(n, hand.DOFS_PER_HAND, dtype=np.int64), 0.0,
                         SagTables.empty(), np.full(n, -np.inf), np.full(n, np.inf))

    def full_pose(self, controls_deg: FloatArray, inclination_deg: float,
                  rotation_deg: float) -> FloatArray:
        """The take's pose as it is (its sag recorded with it), not yet clamped."""
        self.pose[:] = controls_deg
        return self.pose


def copy_pose(raw: FloatArray, t_s: float, out: FloatArray) -> FloatArray:
    """The loop's controls from a take's frame: its pose values, unfiltered (the
    ControlsFromRaw of a performance played onto the servos)."""
    out[:] = raw
    return out
