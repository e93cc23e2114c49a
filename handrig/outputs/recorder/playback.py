"""Play a recorded performance back on a clock at its recorded times: :class:`Playback`."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from handrig.clock import Clock
from handrig.errors import DataError
from handrig.outputs.recorder.loading import load_performance


class Playback:
    """Play a recorded performance back on ``clock`` at its recorded times.

    Two ways to use it: iterate (``for t_s, pose, wrist in playback``), which sleeps on
    the clock until each frame is due; or, from a fixed-rate loop, call :meth:`start`
    once and :meth:`sample` every tick, which never blocks and returns the latest frame
    due. ``speed`` scales time (2.0 plays twice as fast); ``loop`` starts over at the end.
    ``wrist`` is None when the recording has no wrist DOFs.
    """

    def __init__(self, path: str | Path, clock: Clock, *, speed: float = 1.0,
                 loop: bool = False) -> None:
        if not (math.isfinite(speed) and speed > 0):
            raise DataError(f"{path}: playback speed must be positive, got {speed}")
        self.path = Path(path)
        self.t_s, self.poses, self.wrist = load_performance(self.path)
        self.clock = clock
        self.speed = float(speed)
        self.loop = loop
        self._rel_s = self.t_s - self.t_s[0]
        period = float(np.median(np.diff(self._rel_s))) if len(self._rel_s) > 1 else 0.0
        self.duration_s = float(self._rel_s[-1]) + period
        self._start_s = 0.0

    @property
    def n_frames(self) -> int:
        return int(self.t_s.shape[0])

    def start(self) -> None:
        """Start the performance now (on the clock)."""
        self._start_s = self.clock.now()

    def elapsed_s(self) -> float:
        """Performance time since :meth:`start` (scaled by ``speed``), seconds."""
        return (self.clock.now() - self._start_s) * self.speed

    def index_at(self, now_s: float) -> int | None:
        """Index of the frame due at clock time ``now_s``; None after the end (no loop)."""
        rel = (now_s - self._start_s) * self.speed
        if self.loop and self.duration_s > 0:
            rel %= self.duration_s
        elif rel > self.duration_s:
            return None
        return max(int(np.searchsorted(self._rel_s, rel, side="right")) - 1, 0)

    def sample(self) -> tuple[NDArray[np.float64], NDArray[np.float64] | None] | None:
        """(pose (50,), wrist (4,) or None) due now, or None once it has ended."""
        i = self.index_at(self.clock.now())
        if i is None:
            return None
        return self.poses[i], (self.wrist[i] if self.wrist is not None else None)

    def __iter__(self) -> Iterator[tuple[float, NDArray[np.float64], NDArray[np.float64] | None]]:
        self.start()
        while True:
            for i in range(self.n_frames):
                self.clock.sleep_until(self._start_s + self._rel_s[i] / self.speed)
                yield float(self.t_s[i]), self.poses[i], (
                    self.wrist[i] if self.wrist is not None else None)
            if not self.loop:
                return
            self._start_s += self.duration_s / self.speed
