"""Where a glove frame's latency goes: clock times between the critical path's stages.

:class:`StageProfile` wraps the callables a :class:`~handrig.loop.cycle.Cycle`
calls (glove read, controls, orientation, servo step, goal write) and, for each
cycle in which all of them ran, adds the time each stage took to a histogram.
The cycle's code knows nothing of it; without a profile nothing is wrapped.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from handrig.clock import Clock
from handrig.loop.stats import LogHistogram

STAGES: tuple[str, ...] = ("read+decode", "calibrate+filter", "orientation", "targets", "write")


class StageProfile:
    """Per-stage histograms (seconds) of the cycles that followed a glove frame."""

    def __init__(self, clock: Clock) -> None:
        self.clock = clock
        self.stages: dict[str, LogHistogram] = {name: LogHistogram() for name in STAGES}
        self._hist = [self.stages[name] for name in STAGES]
        self._marks = [math.nan] * (len(STAGES) + 1)

    def wrap(self, cycle: Any) -> None:
        """Replace ``cycle``'s stage callables by timed ones."""
        cycle.latest = self._latest(cycle.latest)
        cycle.controls_from_raw = self._mark(cycle.controls_from_raw, 2)
        cycle.orientation = self._mark(cycle.orientation, 3)
        cycle.targets = self._mark(cycle.targets, 4)
        cycle.write = self._write(cycle.write)

    def summary_us(self) -> dict[str, dict[str, float]]:
        """``{stage: {"p50": us, "p99": us}}`` for the stages measured at least once."""
        return {name: {"p50": round(h.percentile(50) * 1e6, 1),
                       "p99": round(h.percentile(99) * 1e6, 1)}
                for name, h in self.stages.items() if h.count}

    def _latest(self, latest: Callable[[], Any]) -> Callable[[], Any]:
        marks, now = self._marks, self.clock.now

        def timed() -> Any:
            sample = latest()
            for i in range(len(marks)):
                marks[i] = math.nan
            if sample is not None:
                marks[0] = sample.host_time_s
                marks[1] = now()
            return sample
        return timed

    def _mark(self, fn: Callable[..., Any], slot: int) -> Callable[..., Any]:
        marks, now = self._marks, self.clock.now

        def timed(*args: Any) -> Any:
            out = fn(*args)
            marks[slot] = now()
            return out
        return timed

    def _write(self, write: Callable[[Any], int]) -> Callable[[Any], int]:
        marks, now, hist = self._marks, self.clock.now, self._hist

        def timed(goals: Any) -> int:
            n = write(goals)
            marks[-1] = now()
            if not any(m != m for m in marks):  # every stage ran in this cycle
                for i, h in enumerate(hist):
                    h.add(marks[i + 1] - marks[i])
            return n
        return timed
