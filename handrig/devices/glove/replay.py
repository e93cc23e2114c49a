"""A glove recording played against the injected clock: :class:`ReplayGlove`."""

from __future__ import annotations

import math

import numpy as np

from firmware_protocol.glove import BUTTON_RELAX
from handrig.clock import Clock
from handrig.devices.glove.source import BEHIND_KEPT, GloveSample, GloveSource, GloveStats
from handrig.devices.glove_recording import GloveRecording
from handrig.errors import DeviceError

DUE_TOLERANCE_S = 1e-9
""":meth:`ReplayGlove.next_due_s` is this much after the due time, so that the clock
time it gives, less the start, does not round to just before the sample."""


class ReplayGlove(GloveSource):
    """A recording played against the injected clock.

    :meth:`start` (or the first :meth:`latest`) pins recording time ``t_s[0]`` to
    ``clock.now()``; from then ``latest()`` returns the newest recorded sample at or
    before the current time, once. Its ``host_time_s`` is the clock time at which
    that sample was due, so latency measured from it includes how late the loop
    picked it up. With ``loop=True`` the recording repeats (one median sample
    period between the last and the first sample); otherwise :attr:`finished`
    turns true after the last sample and ``latest()`` returns ``None``.
    ``start_at_first_look``: :meth:`start` does not pin the start; the loop's first look
    (``latest``, ``next_due_s``) does, so a take played onto the servos begins when the
    loop does, not while the bus is commissioned.
    """

    def __init__(self, recording: GloveRecording, clock: Clock, *, loop: bool = False,
                 start_at_first_look: bool = False) -> None:
        super().__init__()
        if len(recording) == 0:
            raise DeviceError("glove recording is empty: nothing to replay")
        self.recording = recording
        self.clock = clock
        self.loop = loop
        self.start_at_first_look = start_at_first_look
        t = recording.t_s
        gap = float(np.median(np.diff(t))) if len(t) > 1 else 0.01
        self._period_s = float(t[-1] - t[0]) + gap
        self._t_rel = t - t[0]
        self._t0: float | None = None
        self._served = 0
        self._skipped = 0

    @property
    def name(self) -> str:
        return "replay"

    def start(self) -> None:
        if self._t0 is None and not self.start_at_first_look:
            self._t0 = self.clock.now()

    @property
    def finished(self) -> bool:
        """Not looping and the last sample has been due."""
        if self.loop or self._t0 is None:
            return False
        return self.clock.now() - self._t0 >= self._t_rel[-1]

    def latest(self) -> GloveSample | None:
        if self._t0 is None:
            self._t0 = self.clock.now()
        lap, i = self._due_index(self.clock.now() - self._t0)
        if i < 0:
            return None
        count = lap * len(self._t_rel) + i + 1
        if count <= self._taken:
            return None
        return self._serve(lap, i, count)

    def _serve(self, lap: int, i: int, count: int) -> GloveSample:
        """Recorded sample ``i`` of lap ``lap`` (the ``count``-th), marked taken."""
        rec = self.recording
        q = None if rec.quat_xyzw is None else rec.quat_xyzw[i]
        if q is not None and np.isnan(q).any():
            q = None
        b = int(rec.buttons[i])
        sample = GloveSample(
            raw=rec.raw[i], quat=q, buttons=b, estop=bool(b & BUTTON_RELAX),
            seq=(count - 1) & 0xFFFF, sensor_time_us=int(self._t_rel[i] * 1e6) & 0xFFFFFFFF,
            host_time_s=self._due_at(lap, i), count=count,
        )
        self._skipped += count - self._taken - 1
        if self._taps:
            self._tapped(sample)
        self._newest = sample
        self._taken = count
        self._served += 1
        return sample

    def _behind_index(self) -> tuple[int, int, int] | None:
        """(lap, index, count) of the oldest of the :data:`BEHIND_KEPT` samples due before
        the newest that was not taken, when it came due strictly before the newest (a
        recorded duplicate of the newest's time is not caught up)."""
        if self._t0 is None:
            return None
        n = len(self._t_rel)
        lap, i = self._due_index(self.clock.now() - self._t0)
        count = lap * n + i + 1
        first = max(self._taken + 1, count - BEHIND_KEPT)
        if i < 0 or first >= count:
            return None
        b_lap, b_i = divmod(first - 1, n)
        if self._due_at(b_lap, b_i) >= self._due_at(lap, i):
            return None
        return b_lap, b_i, first

    def has_behind(self) -> bool:
        return self._behind_index() is not None

    def take_behind(self) -> GloveSample | None:
        behind = self._behind_index()
        return None if behind is None else self._serve(*behind)

    def _due_index(self, elapsed: float) -> tuple[int, int]:
        """(lap, index) of the newest recorded sample due ``elapsed`` s after the start."""
        lap = 0
        if self.loop:
            lap = int(elapsed // self._period_s)
            elapsed -= lap * self._period_s
        return lap, int(np.searchsorted(self._t_rel, elapsed, side="right")) - 1

    def _due_at(self, lap: int, i: int) -> float:
        t0 = self._t0 if self._t0 is not None else self.clock.now()
        return t0 + lap * self._period_s + float(self._t_rel[i])

    def has_new(self) -> bool:
        if self._t0 is None:
            return False
        lap, i = self._due_index(self.clock.now() - self._t0)
        return i >= 0 and lap * len(self._t_rel) + i + 1 > self._taken

    def newest_due_s(self) -> float:
        """When the newest sample due by now came due (the clock now before any)."""
        now = self.clock.now()
        if self._t0 is None:
            return now
        lap, i = self._due_index(now - self._t0)
        return self._due_at(lap, i) if i >= 0 else now

    def next_due_s(self) -> float:
        """When the next sample not yet returned comes due (inf after the last one)."""
        if self._t0 is None:
            self._t0 = self.clock.now()
        n = len(self._t_rel)
        lap, i = divmod(self._taken, n)  # the sample after the last one returned
        if not self.loop and lap > 0:
            return math.inf
        due = self._due_at(lap, i) + DUE_TOLERANCE_S
        now = self.clock.now()
        return due if due > now else now

    def stats(self) -> GloveStats:
        since = math.inf
        if self._newest is not None:
            since = self.clock.now() - self._newest.host_time_s
        return GloveStats(frames_ok=self._served, time_since_last_good_s=since,
                          frames_lost=self._skipped)
