"""Easing: from where the servos were last sent to a target, over a fixed time.

Used twice by the loop: to the relaxed pose (glove lost, e-stop, stop request),
and back to the glove's pose when it returns (so a glove that comes back does
not make the servos jump at the slew limit). The blend is a smoothstep
``s = 3a^2 - 2a^3`` of the elapsed fraction ``a``: zero speed at both ends.
The target may move while easing (the glove's pose does); the servo goals and the
full pose for the outputs use the same ``s``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


class Easing:
    """One easing, restartable. Arrays are preallocated; :meth:`goals` and :meth:`pose`
    return views of them that hold until the next call."""

    def __init__(self, n_servos: int, n_pose: int, duration_s: float) -> None:
        self.duration_s = float(duration_s)
        self._from_goals = np.zeros(n_servos)
        self._from_pose = np.zeros(n_pose)
        self._goals = np.zeros(n_servos)
        self._pose = np.zeros(n_pose)
        self._t0: float | None = None
        self.blend = 0.0  # s of the last :meth:`goals` call

    def restart(self) -> None:
        """Start over on the next :meth:`goals` call, from what it is given then. Safe to
        call from a signal handler (one attribute write)."""
        self._t0 = None

    @property
    def started(self) -> bool:
        return self._t0 is not None

    def goals(self, now_s: float, sent: FloatArray, pose_now: FloatArray | None,
              to_goals: FloatArray) -> tuple[FloatArray, bool]:
        """The servo goals at ``now_s`` and whether the easing is complete.

        On the first call after :meth:`restart` the easing starts from ``sent`` (the
        goals last written) and ``pose_now`` (the full pose last output; None: start
        the pose at its target)."""
        if self._t0 is None:
            self._t0 = now_s
            self._from_goals[:] = sent
            self._has_pose = pose_now is not None
            if pose_now is not None:
                self._from_pose[:] = pose_now
        a = (now_s - self._t0) / self.duration_s if self.duration_s > 0 else 1.0
        a = min(1.0, max(0.0, a))
        s = a * a * (3.0 - 2.0 * a)
        self.blend = s
        np.subtract(to_goals, self._from_goals, out=self._goals)
        self._goals *= s
        self._goals += self._from_goals
        return self._goals, a >= 1.0

    def pose(self, to_pose: FloatArray) -> FloatArray:
        """The full pose blended with the same ``s`` as the last :meth:`goals` call."""
        if not self._has_pose:
            self._from_pose[:] = to_pose
            self._has_pose = True
        s = self.blend
        np.multiply(self._from_pose, 1.0 - s, out=self._pose)
        self._pose += s * to_pose
        return self._pose

    _has_pose = False
