"""The runtime half of the reduced hand: a few control angles -> the full 50-curve pose.

:class:`Expander` precomputes ``pose = bias + controls @ gains_t`` and clamps each
curve to its joint limits and to the map's output range of that curve
(:meth:`LinearMap.output_range_deg`, a clipped-linear map); one frame is one compiled
loop (:func:`handrig.pose.kernels.expand_frame`, the training-range count included) on
preallocated buffers (a piecewise-linear map's features first:
:meth:`LinearMap.feature_gains`, :func:`handrig.pose.kernels.hinge_features`), many frames
are numpy calls (``bench/bench_expand.py`` measures both).

A map records the range each control covered in training; the expander counts the
calls whose controls leave it (by more than ``margin_deg``), per control too, so a run
summary can say how often the live glove asked for hand shapes the map never saw (a
glove calibration that is off shows up here first). :meth:`Expander.training_range`
reads the counters. Every :meth:`Expander.expand` call counts as a frame; a caller whose
own path precomposes the map counts frames with :meth:`Expander.note_controls` instead
(one of the two per frame, not both).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.config.loading import CONFIG_DIR, JointLimits, load_joint_limits
from handrig.errors import DataError
from handrig.pose import kernels as pose_kernels
from handrig.pose.maps import LinearMap

FloatArray = NDArray[np.float64]
DEFAULT_MAP = CONFIG_DIR / "maps" / "default.toml"
"""Right-glove map shipped with handrig (fitted on data/mocap/pn_gestures_reference.bvh)."""
DEFAULT_TWO_GLOVE_MAP = CONFIG_DIR / "maps" / "default_two_gloves.toml"
RANGE_MARGIN_DEG = 2.0
"""A control counts as outside its training range beyond this many degrees past it."""


@dataclass(frozen=True)
class TrainingRangeReport:
    """How often the controls left the map's training range (see :class:`Expander`).

    ``known`` is False for a map without a recorded range (then every count is 0).
    ``outside_by_control`` maps each control to the number of frames it was outside.
    """

    known: bool
    frames: int
    outside_frames: int
    outside_by_control: dict[str, int]
    margin_deg: float

    @property
    def outside_fraction(self) -> float:
        return self.outside_frames / self.frames if self.frames else 0.0

    def summary(self) -> str:
        """One line for a run summary."""
        if not self.known:
            return "training range unknown (the map records none: refit it with handrig fit-map)"
        if not self.outside_frames:
            return (f"controls inside the map's training range in all {self.frames} frames"
                    f" (margin {self.margin_deg:g} deg)")
        worst = sorted(self.outside_by_control.items(), key=lambda kv: -kv[1])
        shown = ", ".join(f"{c} {n / self.frames:.0%}" for c, n in worst[:3] if n)
        return (f"controls outside the map's training range in {self.outside_frames} of"
                f" {self.frames} frames ({self.outside_fraction:.1%}; {shown}): check the"
                " glove calibration")

    def to_json(self) -> dict[str, object]:
        return {"known": self.known, "frames": self.frames,
                "outside_frames": self.outside_frames,
                "outside_fraction": round(self.outside_fraction, 6),
                "outside_by_control": dict(self.outside_by_control),
                "margin_deg": self.margin_deg}


class Expander:
    """Expands control angles (degrees, vocabulary convention) into all 50 curves.

    ``controls``: the control curve names, in the order of the input vector;
    ``curve_names``: :data:`handrig.hand.CURVE_NAMES`; ``control_means_deg``: each
    control's mean in training (use it for a channel the glove lacks).
    """

    def __init__(self, map: LinearMap, limits: JointLimits | None = None, *,
                 range_margin_deg: float = RANGE_MARGIN_DEG) -> None:
        self.map = map
        self.controls: tuple[str, ...] = tuple(map.controls)
        self.curve_names: tuple[str, ...] = hand.CURVE_NAMES
        self.control_means_deg: FloatArray = np.array(map.control_means_deg, dtype=np.float64)
        lim = limits if limits is not None else load_joint_limits()
        bounds = np.array([lim.of(n) for n in hand.CURVE_NAMES], dtype=np.float64)
        clip = map.output_range_deg()
        # the map's range inside the joint limits (a range wholly outside them: the limit)
        low = np.minimum(np.maximum(bounds[:, 0], clip[:, 0]), bounds[:, 1])
        high = np.maximum(np.minimum(bounds[:, 1], clip[:, 1]), low)
        self.low_deg: FloatArray = np.ascontiguousarray(low)
        self.high_deg: FloatArray = np.ascontiguousarray(high)
        # pose = curve_means + gains @ (c - control_means) = bias + f @ gains_f.T, where the
        # features f are the controls (and, piecewise-linear, their hinges at the knots)
        gains_f, bias, knots = map.feature_gains()
        self._gains_t: FloatArray = np.ascontiguousarray(gains_f.T, dtype=np.float64)
        self._bias: FloatArray = np.ascontiguousarray(bias, dtype=np.float64)
        self._knots: FloatArray = np.ascontiguousarray(knots, dtype=np.float64)
        self._k = len(self.controls)
        self._features: FloatArray = np.zeros(self._k + len(knots))
        self._out: FloatArray = np.zeros(len(self.curve_names))
        # Training range counters: preallocated, updated with out= calls per frame.
        self.range_margin_deg = float(range_margin_deg)
        self._range_known = map.control_range_deg is not None
        rng = (np.asarray(map.control_range_deg, dtype=np.float64) if self._range_known
               else np.array([[-np.inf, np.inf]] * self._k))
        self.train_low_deg: FloatArray = np.ascontiguousarray(rng[:, 0] - self.range_margin_deg)
        self.train_high_deg: FloatArray = np.ascontiguousarray(rng[:, 1] + self.range_margin_deg)
        self._below = np.zeros(self._k, dtype=bool)
        self._above = np.zeros(self._k, dtype=bool)
        # one count per feature (a hinge feature is never outside: its range is open)
        h = len(knots)
        self._feature_low: FloatArray = np.concatenate([self.train_low_deg, np.full(h, -np.inf)])
        self._feature_high: FloatArray = np.concatenate([self.train_high_deg,
                                                         np.full(h, np.inf)])
        self._outside_counts = np.zeros(self._k + h, dtype=np.int64)
        self.frames = 0
        self.outside_frames = 0
        self._range_t: FloatArray = np.ascontiguousarray(np.hstack([np.eye(self._k),
                                                                   -np.eye(self._k)]))
        self._range_bias: FloatArray = np.ascontiguousarray(np.concatenate([
            -np.where(np.isfinite(self.train_low_deg), self.train_low_deg, 0.0),
            np.where(np.isfinite(self.train_high_deg), self.train_high_deg, 0.0)]))
        self._gap: FloatArray = np.zeros(2 * self._k)
        pose_kernels.warm_up()

    @classmethod
    def from_file(cls, path: str | Path | None = None, limits: JointLimits | None = None
                  ) -> Expander:
        """Build from a map TOML file (None: ``config/maps/default.toml``)."""
        return cls(LinearMap.load(path if path is not None else DEFAULT_MAP), limits)

    def expand(self, controls_deg: FloatArray, out: FloatArray | None = None) -> FloatArray:
        """One frame: ``controls_deg`` (k,) -> pose (50,), clamped to the joint limits.

        Writes into ``out`` (float64, shape (50,), C-contiguous) if given, else into a
        buffer owned by the expander that the next call overwrites (copy to keep it).
        """
        if out is None:
            out = self._out
        c = controls_deg if type(controls_deg) is np.ndarray else np.asarray(
            controls_deg, dtype=np.float64)
        if c.shape != (self._k,):
            raise DataError(
                f"expected {self._k} control values ({', '.join(self.controls)}), got shape"
                f" {c.shape}"
            )
        if c.dtype != np.float64 or not c.flags.c_contiguous:
            c = np.ascontiguousarray(c, dtype=np.float64)
        self.frames += 1
        if self._knots.shape[0]:
            pose_kernels.hinge_features(c, self._knots, self._features)
            c = self._features
        if pose_kernels.expand_frame(c, self._gains_t, self._bias, self.low_deg, self.high_deg,
                                     self._feature_low, self._feature_high, out,
                                     self._outside_counts):
            self.outside_frames += 1
        return out

    def note_controls(self, controls_deg: FloatArray) -> bool:
        """Count one frame of controls against the training range without expanding it
        (for a caller whose own path precomposes the map); True if any was outside."""
        c = controls_deg
        if c.shape != (self._k,):
            raise DataError(f"expected {self._k} control values, got shape {c.shape}")
        self.frames += 1
        if not self._range_known:
            return False
        np.dot(c, self._range_t, out=self._gap)
        np.add(self._gap, self._range_bias, out=self._gap)
        if self._gap.min() < 0.0:
            self._count_outside(c)
            return True
        return False

    def _count_outside(self, c: FloatArray) -> None:
        self.outside_frames += 1
        np.less(c, self.train_low_deg, out=self._below)
        np.greater(c, self.train_high_deg, out=self._above)
        np.logical_or(self._below, self._above, out=self._below)
        np.add(self._outside_counts[:self._k], self._below, out=self._outside_counts[:self._k])

    def expand_many(self, controls_deg: FloatArray, out: FloatArray | None = None) -> FloatArray:
        """Many frames: (n, k) -> (n, 50), clamped; ``out`` (n, 50) is reused if given."""
        c = np.asarray(controls_deg, dtype=np.float64)
        if c.ndim != 2 or c.shape[1] != self._k:
            raise DataError(
                f"expected (frames, {self._k}) controls ({', '.join(self.controls)}), got"
                f" shape {c.shape}"
            )
        if out is None:
            out = np.empty((c.shape[0], len(self.curve_names)))
        f = c
        if self._knots.shape[0]:
            f = np.hstack([c, np.maximum(c - self._knots, 0.0)])
        np.matmul(f, self._gains_t, out=out)
        out += self._bias
        np.clip(out, self.low_deg, self.high_deg, out=out)
        outside = (c < self.train_low_deg) | (c > self.train_high_deg)
        self.frames += c.shape[0]
        self.outside_frames += int(outside.any(axis=1).sum())
        self._outside_counts[:self._k] += outside.sum(axis=0)
        return out

    def training_range(self) -> TrainingRangeReport:
        """The counters since construction (or :meth:`reset_training_range`)."""
        return TrainingRangeReport(
            known=self._range_known, frames=self.frames, outside_frames=self.outside_frames,
            outside_by_control={c: int(n) for c, n in zip(
                self.controls, self._outside_counts[:self._k], strict=True)},
            margin_deg=self.range_margin_deg,
        )

    def reset_training_range(self) -> None:
        """Zero the training range counters."""
        self.frames = 0
        self.outside_frames = 0
        self._outside_counts[:] = 0
