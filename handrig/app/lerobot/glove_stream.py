"""The glove in a thread of its own, its poses kept with their times; the frame grid.

LeRobot's record loop (``lerobot-record``, 0.4.4) runs once a frame: read the robot,
ask the teleoperator for its action, send it, add the frame, then sleep ``1/fps`` less
the time the iteration took. The dataset stamps frame ``k`` of an episode at exactly
``k / fps``; the loop itself drifts later than that by every oversleep and slow
iteration. A teleoperator that answers with whatever is newest when asked therefore
hands frame ``k`` the pose of some moment after ``k / fps``, further off each frame.

:class:`FrameGrid` gives each call its frame's time instead: the first call of a run
anchors frame 0, call ``k`` is frame ``k``, due at ``anchor + k / fps``. A call that
comes more than :data:`GAP_FRAMES` frames after the one before starts a new run (a new
episode after the reset, a new ``lerobot-teleoperate``); a loop that has fallen more
than ``max_lag_s`` behind its grid is re-anchored and counted (its frames before and
after are not evenly spaced in time, and the caller says so). :class:`GloveStream`
answers "the newest pose at time t" from a ring of every sample the glove sent, each
put through the pipeline as it arrived (never averaged, never a sample from after t).
"""

from __future__ import annotations

import select
import threading
from collections import deque
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from handrig.clock import Clock
from handrig.devices.glove.source import GloveSample, GloveSource
from handrig.errors import DeviceError, DeviceTimeoutError

FloatArray = NDArray[np.float64]
GAP_FRAMES = 3.0
""":class:`FrameGrid`: a call this many frame periods after the last one starts a new run."""
WAKE_S = 0.005
""":class:`GloveStream`: the longest its thread sleeps without looking at the glove."""
CATCH_UP_S = 0.5
""":meth:`GloveStream.pose_at`: how long it waits for the thread to have looked at the
glove up to the asked time before answering from what it has (counted in
:attr:`GloveStream.late_answers`). The wait is only ever long when the thread has not
run: a machine busy enough to starve it (at nice 10 beside two busy cores it went
more than the 50 ms this was before without running, and a frame of LeRobot's record
got a row from 10 ms before its time)."""


class FrameGrid:
    """The time of the frame a call belongs to, for a caller that asks once a frame at
    ``fps`` (module docstring). ``max_lag_s``: how far behind its grid the caller may fall
    before the grid is re-anchored at the call."""

    def __init__(self, fps: float, max_lag_s: float) -> None:
        self.period_s = 1.0 / fps
        self.max_lag_s = max_lag_s
        self._anchor: float | None = None
        self._k = 0
        self._last_call = -np.inf
        self.runs = 0
        """Runs begun (a first call, or one after a gap)."""
        self.reanchored = 0
        """Times the caller fell more than ``max_lag_s`` behind its grid."""
        self.early = 0
        """Calls that came more than half a frame before their frame's time (a caller
        asking faster than ``fps``): each is re-anchored at the call, so gets its own
        time (the newest pose), and is counted here, not in :attr:`reanchored`."""
        self.worst_lag_s = 0.0
        """The latest a call came after its frame's time, over the current run."""

    def frame_time(self, now: float) -> float:
        """The time of the frame this call (made at ``now``) is for; at most half a frame
        after ``now`` (a caller that comes early waits for it)."""
        gap = now - self._last_call
        self._last_call = now
        if self._anchor is None or gap > GAP_FRAMES * self.period_s:
            self._start(now)
            self.runs += 1
        due = self._anchor + self._k * self.period_s  # type: ignore[operator]
        lag = now - due
        if lag > self.max_lag_s or lag < -0.5 * self.period_s:
            if lag > 0.0:
                self.reanchored += 1
            else:
                self.early += 1
            self._start(now)
            due, lag = now, 0.0
        self.worst_lag_s = max(self.worst_lag_s, lag)
        self._k += 1
        return due

    def _start(self, now: float) -> None:
        self._anchor, self._k, self.worst_lag_s = now, 0, 0.0


PoseOf = Callable[[GloveSample], FloatArray]


class GloveStream:
    """``glove`` read in a thread of its own as its samples come; each put through
    ``pose_of`` (the pipeline: calibration, map, sag, limits, a robot's retarget) and
    kept with its ``host_time_s`` for ``keep_s`` seconds. :meth:`pose_at` answers from
    them and never touches the port. A context manager: the thread starts and stops
    with it (and the glove with it)."""

    def __init__(self, glove: GloveSource, pose_of: PoseOf, clock: Clock, *,
                 keep_s: float = 2.0, expected_hz: float = 1000.0) -> None:
        self.glove = glove
        self._pose_of = pose_of
        self._clock = clock
        self._ring: deque[tuple[float, FloatArray]] = deque(
            maxlen=max(16, int(keep_s * expected_hz)))
        self._looked_until = -np.inf  # the clock time up to which every sample is in
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None
        self.samples = 0
        self.lost = 0
        """Samples the glove superseded before the thread took them (a gap in their
        counts: the thread had not run for longer than the glove keeps samples behind
        its newest, ``BEHIND_KEPT``): a pose asked for their time gets an older one."""
        self.late_answers = 0
        """:meth:`pose_at` calls answered before the thread had looked at the glove up
        to the asked time (it had not run for :data:`CATCH_UP_S`): the pose may be older."""
        self._last_count: int | None = None

    def __enter__(self) -> GloveStream:
        self.glove.start()
        self._thread = threading.Thread(target=self._run, name="handrig-lerobot-glove",
                                        daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the thread and close the glove. Idempotent."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self.glove.close()

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                self._wait_for_glove()
                looked = self._clock.now()
                batch = []
                while (s := self.glove.take_behind()) is not None:
                    batch.append(s)
                if (s := self.glove.latest()) is not None:
                    batch.append(s)
                posed = [(s.host_time_s, self._pose_of(s)) for s in batch]
                lost = 0
                for s in batch:
                    if self._last_count is not None and s.count > self._last_count + 1:
                        lost += s.count - self._last_count - 1
                    self._last_count = s.count
                with self._cond:
                    self._ring.extend(posed)
                    self.samples += len(posed)
                    self.lost += lost
                    self._looked_until = looked
                    self._cond.notify_all()
        except BaseException as exc:  # handed to the caller by check()
            self.error = exc
            with self._cond:
                self._cond.notify_all()

    def _wait_for_glove(self) -> None:
        fd = self.glove.fileno()
        if fd is not None:
            readable, _, _ = select.select([fd], [], [], WAKE_S)
            if readable:
                self.glove.pump()
            return
        now = self._clock.now()
        due = self.glove.next_due_s()
        self._clock.sleep_until(min(due, now + WAKE_S) if due is not None else now + WAKE_S)

    def check(self) -> None:
        """Raise what stopped the thread, or the glove's failure."""
        if self.error is not None:
            raise DeviceError(f"the glove's thread stopped: {self.error}") from self.error
        self.glove.check()

    def pose_at(self, t_s: float) -> tuple[float, FloatArray] | None:
        """(its time, the pose) of the newest sample at or before clock time ``t_s``, once
        the thread has looked at the glove up to ``t_s`` (waiting up to
        :data:`CATCH_UP_S`); None when no sample that old is kept (none yet, or
        ``t_s`` before the ring)."""
        self.check()
        with self._cond:
            deadline = self._clock.now() + CATCH_UP_S
            while self._looked_until < t_s and self.error is None:
                left = deadline - self._clock.now()
                if left <= 0.0:
                    self.late_answers += 1
                    break
                self._cond.wait(left)
            for t, pose in reversed(self._ring):
                if t <= t_s:
                    return t, pose
        self.check()
        return None

    def wait_first(self, timeout_s: float) -> None:
        """Until the first sample is in; DeviceTimeoutError after ``timeout_s``."""
        with self._cond:
            deadline = self._clock.now() + timeout_s
            while not self._ring and self.error is None:
                left = deadline - self._clock.now()
                if left <= 0.0:
                    raise DeviceTimeoutError(
                        f"no glove sample from {self.glove.name} in {timeout_s:g} s: is "
                        "the glove plugged in and sending (handrig glove-monitor)?")
                self._cond.wait(left)
        self.check()
