"""Clocks: the only place handrig reads time.

Realtime code takes a :class:`Clock` as a dependency. :class:`MonotonicClock`
is the real one (``time.perf_counter``, never wall time); :class:`FakeClock`
lets tests step time deterministically.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod


class Clock(ABC):
    """Monotonic time in seconds, and sleeping until a point on that time line."""

    @abstractmethod
    def now(self) -> float:
        """Seconds on a monotonic time line (arbitrary origin)."""

    @abstractmethod
    def sleep_until(self, t: float) -> None:
        """Return at (or as soon as possible after) time ``t``; return at once if past."""

    def sleep(self, dt: float) -> None:
        """Sleep for ``dt`` seconds."""
        self.sleep_until(self.now() + dt)


class MonotonicClock(Clock):
    """The real clock: ``time.perf_counter``, with a short spin for the last stretch.

    ``spin_s`` is how long before the deadline the clock stops sleeping and spins;
    OS sleeps overshoot by 50-100 us, which a 200 Hz loop notices as jitter.
    """

    def __init__(self, spin_s: float = 0.0002) -> None:
        if spin_s < 0:
            raise ValueError(f"spin_s must be >= 0, got {spin_s}")
        self.spin_s = spin_s

    def now(self) -> float:
        return time.perf_counter()

    def sleep_until(self, t: float) -> None:
        remaining = t - time.perf_counter()
        if remaining > self.spin_s:
            time.sleep(remaining - self.spin_s)
        while time.perf_counter() < t:
            pass


class FakeClock(Clock):
    """A clock that only moves when told: ``sleep_until`` jumps straight to the deadline."""

    def __init__(self, start: float = 0.0) -> None:
        self._t = float(start)
        self.sleeps = 0

    def now(self) -> float:
        return self._t

    def sleep_until(self, t: float) -> None:
        self.sleeps += 1
        if t > self._t:
            self._t = float(t)

    def advance(self, dt: float) -> None:
        """Move time forward by ``dt`` seconds (``dt`` >= 0)."""
        if dt < 0:
            raise ValueError(f"time cannot go backwards (dt={dt})")
        self._t += dt
