"""Where a glove frame's latency goes: clock times between the critical path's stages.

:class:`StageProfile` wraps the callables a :class:`~handrig.loop.cycle.Cycle`
calls (glove read, controls, orientation, servo step, goal write) and, for each
cycle in which all of them ran, adds the time each stage took to a histogram.
The cycle's code knows nothing of it; without a profile nothing is wrapped.
"""

from __future__ import annotations

import math
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
        """Replace ``cycle``'s stage callables by timed ones. The timing costs one clock
        read per stage inside the latency it measures; the bookkeeping runs before the
        next glove read, outside it."""
        marks, now = self._marks, self.clock.now
        latest, controls = cycle.latest, cycle.controls_from_raw
        orientation, targets, write = cycle.orientation, cycle.targets, cycle.write

        def timed_latest() -> Any:
            self._flush()
            sample = latest()
            if sample is not None:
                marks[0] = sample.host_time_s
                marks[1] = now()
            return sample

        def timed_controls(raw: Any, t_s: float, out: Any) -> Any:
            result = controls(raw, t_s, out)
            marks[2] = now()
            return result

        def timed_orientation(sample: Any) -> tuple[float, float]:
            result = orientation(sample)
            marks[3] = now()
            return result

        def timed_targets(c: Any, inclination: float, rotation: float, dt_s: float) -> Any:
            result = targets(c, inclination, rotation, dt_s)
            marks[4] = now()
            return result

        def timed_write(goals: Any) -> int:
            n = write(goals)
            marks[5] = now()
            return n

        cycle.latest = timed_latest
        cycle.controls_from_raw = timed_controls
        cycle.orientation = timed_orientation
        cycle.targets = timed_targets
        cycle.write = timed_write

    def summary_us(self) -> dict[str, dict[str, float]]:
        """``{stage: {"p50": us, "p99": us}}`` for the stages measured at least once."""
        self._flush()
        return {name: {"p50": round(h.percentile(50) * 1e6, 1),
                       "p99": round(h.percentile(99) * 1e6, 1)}
                for name, h in self.stages.items() if h.count}

    def _flush(self) -> None:
        """The last cycle's stage times into the histograms, if every stage ran in it."""
        marks = self._marks
        if not any(m != m for m in marks):
            for i, h in enumerate(self._hist):
                h.add(marks[i + 1] - marks[i])
        for i in range(len(marks)):
            marks[i] = math.nan
