"""The runtime half of the reduced hand: a few control angles -> the full 50-curve pose.

:class:`Expander` precomputes ``pose = bias + controls @ gains_t`` and clamps to the
joint limits, all with ``out=`` numpy calls on preallocated buffers: no Python loop
over curves, no allocation per frame (``bench/bench_expand.py`` measures it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.config import CONFIG_DIR, JointLimits, load_joint_limits
from handrig.errors import DataError
from handrig.maps import LinearMap

FloatArray = NDArray[np.float64]
DEFAULT_MAP = CONFIG_DIR / "maps" / "default.toml"
"""Right-glove map shipped with handrig (fitted on data/mocap/pn_gestures_reference.bvh)."""
DEFAULT_TWO_GLOVE_MAP = CONFIG_DIR / "maps" / "default_two_gloves.toml"


class Expander:
    """Expands control angles (degrees, vocabulary convention) into all 50 curves.

    ``controls``: the control curve names, in the order of the input vector;
    ``curve_names``: :data:`handrig.hand.CURVE_NAMES`; ``control_means_deg``: each
    control's mean in training (use it for a channel the glove lacks).
    """

    def __init__(self, map: LinearMap, limits: JointLimits | None = None) -> None:
        self.map = map
        self.controls: tuple[str, ...] = tuple(map.controls)
        self.curve_names: tuple[str, ...] = hand.CURVE_NAMES
        self.control_means_deg: FloatArray = np.array(map.control_means_deg, dtype=np.float64)
        lim = limits if limits is not None else load_joint_limits()
        bounds = np.array([lim.of(n) for n in hand.CURVE_NAMES], dtype=np.float64)
        self.low_deg: FloatArray = np.ascontiguousarray(bounds[:, 0])
        self.high_deg: FloatArray = np.ascontiguousarray(bounds[:, 1])
        # pose = curve_means + gains @ (c - control_means) = bias + c @ gains.T
        self._gains_t: FloatArray = np.ascontiguousarray(map.gains.T, dtype=np.float64)
        self._bias: FloatArray = np.ascontiguousarray(
            map.curve_means_deg - map.gains @ map.control_means_deg, dtype=np.float64
        )
        self._k = len(self.controls)
        self._out: FloatArray = np.zeros(len(self.curve_names))

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
        np.dot(c, self._gains_t, out=out)
        np.add(out, self._bias, out=out)
        np.clip(out, self.low_deg, self.high_deg, out=out)
        return out

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
        np.matmul(c, self._gains_t, out=out)
        out += self._bias
        np.clip(out, self.low_deg, self.high_deg, out=out)
        return out
