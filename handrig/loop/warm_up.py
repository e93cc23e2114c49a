"""The warm-up: a frame's path rehearsed on scratch data shortly before the frame comes.

On a machine shared with other work, the caches have forgotten the loop's code and
tables by the time the next glove frame comes (5 ms later at 200 Hz), and the frame's
path (decode, compiled step, goal packet) then runs several times slower than it does
warm. :class:`WarmUp` has the trigger run the cycle's rehearsal (which changes nothing
the loop reads) ``lead_s`` before each expected frame, once per frame, so that the
frame finds them in the caches. The trade-off (CPU against felt latency), measured with
``python -m bench felt``, is in docs/measurements.md.
"""

from __future__ import annotations

from collections.abc import Callable

from handrig.realtime import CpuWake

REHEARSAL_ROOM_S = 0.0001
"""A rehearsal takes 30-60 us with the caches cold: it is left out when less than this
is left before the frame, which it would otherwise delay."""
WAKE_LATE_GAIN = 0.125  # weight of the newest wake-up in how late they come
WAKE_LATE_MAX_S = 0.0003  # one wake-up counts for at most this late (a host stall is not news)


class WarmUp:
    """When to rehearse for each expected frame, and the rehearsal itself (``lead_s``:
    how long before the frame; 0, or no rehearsal given: never).

    The wake-up for it is asked for early by how late such wake-ups came
    (:attr:`wake_late_s`, learnt through :meth:`woke`): on a machine whose idle CPUs halt
    (a virtual machine), a sleep of a few milliseconds ends 14-176 us late (p50 50 us on
    the 2-core VM of docs/measurements.md), which left no room for the rehearsal before
    more than half of the frames."""

    def __init__(self, lead_s: float) -> None:
        if not lead_s >= 0.0:
            raise ValueError(f"need a warm-up lead >= 0 s, got {lead_s}")
        self.lead_s = lead_s
        self.count = 0  # rehearsals run
        self._rehearse: Callable[[], None] | None = None
        self._done_for = float("nan")  # the expected frame the last rehearsal was for
        self.wake_late_s = 0.0  # how late a wake-up asked for by :meth:`at` comes (learnt)
        self.keep_awake = CpuWake()  # held from each rehearsal until the frame's write is out

    def rehearse_with(self, rehearse: Callable[[], None]) -> None:
        """Run ``rehearse`` before each expected frame; it must change nothing the loop
        reads and never block."""
        self._rehearse = rehearse

    def at(self, expected_s: float, until_s: float) -> float | None:
        """When to wake to rehearse for the frame expected at ``expected_s`` (NaN: not
        known yet), for a wait that ends at ``until_s``: ``lead_s`` before it, less the
        wake-up's learnt lateness; None when not in this wait: no rehearsal, the period
        unknown, done for this frame, or due after the wait."""
        if (self._rehearse is None or not self.lead_s > 0.0 or expected_s != expected_s
                or expected_s == self._done_for):
            return None
        at = expected_s - self.lead_s - self.wake_late_s
        return at if at < until_s else None

    def woke(self, asked_s: float, now_s: float) -> None:
        """A sleep until ``asked_s`` (from :meth:`at`) ended at ``now_s``: learnt from (a
        clock that did not move with the sleep, a test's, teaches nothing). Only waits
        that begin before ``asked_s`` sleep and learn: at 200 Hz they begin milliseconds
        early; a glove so fast that they never do keeps the lateness last learnt."""
        if now_s >= asked_s:
            late = min(now_s - asked_s, WAKE_LATE_MAX_S)
            self.wake_late_s += WAKE_LATE_GAIN * (late - self.wake_late_s)

    def run(self, expected_s: float, now_s: float) -> None:
        """The rehearsal for the frame expected at ``expected_s``, unless too little time
        is left before it at ``now_s``; either way, none more for that frame. The CPUs
        are kept awake from here (:attr:`keep_awake`) until :meth:`done`."""
        self._done_for = expected_s
        self.keep_awake.hold()
        if self._rehearse is not None and now_s < expected_s - REHEARSAL_ROOM_S:
            self._rehearse()
            self.count += 1

    def done(self) -> None:
        """The frame's Sync Write is out (the trigger settles its tick, or the next wait
        begins): the CPUs may halt again."""
        self.keep_awake.release()
