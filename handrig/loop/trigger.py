"""When a cycle runs: the loop asks its trigger for the next tick.

:class:`FixedRateTrigger` ticks at ``rate_hz`` on the injected clock; a tick
that comes later than a whole period skips the slots it missed (an overrun,
counted with its size). A trigger may run a rehearsal shortly before a tick (see
:mod:`handrig.loop.rehearsal`). Another trigger (one woken by the glove's
frames, say) subclasses :class:`Trigger`; nothing else in the loop changes.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

from handrig.clock import Clock


@dataclass
class Tick:
    """One cycle's timing. ``deadline_s``: the slot the cycle runs in; ``now_s``: when it
    started; ``next_s``: when the next cycle is due (a read must be done by then);
    ``late_s``: how late the cycle started; ``skipped``: whole slots missed before it."""

    index: int = 0
    deadline_s: float = 0.0
    now_s: float = 0.0
    next_s: float = 0.0
    late_s: float = 0.0
    skipped: int = 0


class Trigger(ABC):
    """What starts each cycle."""

    period_s: float

    @abstractmethod
    def start(self, t0_s: float) -> None:
        """The first tick is due at ``t0_s``."""

    @abstractmethod
    def wait(self, tick: Tick, warm: Callable[[float], None] | None = None) -> Tick:
        """Block until the next cycle is due and fill ``tick`` in (returned). ``warm(now)``,
        if given, may be called once shortly before that."""


class FixedRateTrigger(Trigger):
    """A tick every ``1 / rate_hz`` seconds from the start, on ``clock``.

    ``warm_s`` before each deadline the trigger wakes and calls ``warm``, then sleeps
    out the rest; 0 skips that step.
    """

    def __init__(self, clock: Clock, rate_hz: float, *, warm_s: float = 0.0) -> None:
        if not rate_hz > 0.0:
            raise ValueError(f"rate_hz must be positive, got {rate_hz}")
        self.clock = clock
        self.period_s = 1.0 / rate_hz
        self.warm_s = max(0.0, float(warm_s))
        self._t0 = 0.0
        self._k = 0

    def start(self, t0_s: float) -> None:
        self._t0 = t0_s
        self._k = 0

    def wait(self, tick: Tick, warm: Callable[[float], None] | None = None) -> Tick:
        clock, period = self.clock, self.period_s
        deadline = self._t0 + self._k * period
        if warm is not None and self.warm_s > 0 and clock.now() < deadline - self.warm_s:
            clock.sleep_until(deadline - self.warm_s)
            warm(clock.now())
        clock.sleep_until(deadline)
        now = clock.now()
        late = now - deadline
        skipped = 0
        if late > period:
            skipped = int(late / period)
            self._k += skipped
            deadline = self._t0 + self._k * period  # this cycle's slot
        tick.index = self._k
        tick.deadline_s = deadline
        tick.now_s = now
        tick.next_s = deadline + period
        tick.late_s = late
        tick.skipped = skipped
        self._k += 1
        return tick
