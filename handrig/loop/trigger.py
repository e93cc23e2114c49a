"""When a cycle runs: the loop asks its trigger for the next tick.

:class:`FixedRateTrigger` ticks at ``rate_hz`` on the injected clock; a tick
that comes later than a whole period skips the slots it missed (an overrun,
counted with its size). :class:`GloveTrigger` ticks when a glove frame arrives,
with a floor rate (a tick at least every ``1 / floor_hz``, frame or not: the
servos stay fed and their Bus Watchdog armed) and a ceiling (at most ``ceiling_hz``
ticks a second on average, ``CEILING_BURST`` of them back to back: frames that came
late and the one on time after them all get their cycle; a glove faster than the
ceiling is held back, and its cycle takes the newest frame). With ``catch_up``, a
frame superseded before its cycle began (a loop held up two periods or more, by a
slow read or the host, or frames the glove sent together) still gets its cycle: the
tick asks for the oldest frame the glove keeps behind the newest (up to
``handrig.devices.glove.BEHIND_KEPT``), and the ticks for the rest and the newest follow at
once, all within the ceiling's burst.

Both triggers stamp frame arrivals when the glove offers a file descriptor
(:meth:`~handrig.devices.glove.source.GloveSource.fileno`; ``pump()`` reads what
is there and stamps it with the clock): while they wait they block on the
descriptor and pump as soon as bytes arrive, so a sample's ``host_time_s`` is the
time its last byte became readable, not the time a cycle got round to it. A glove
without a descriptor that says when its next sample is due (``next_due_s()``, a
replay) is waited for by sleeping until then.

The trigger also says whether a present-state read fits the time left before
the next tick (:meth:`Trigger.read_deadline`) and whether a read delayed a
write (:meth:`Trigger.delayed`).
"""

from __future__ import annotations

import math
import select
from abc import ABC, abstractmethod
from dataclasses import dataclass

from handrig.clock import Clock, MonotonicClock
from handrig.config.rig import LoopConfig
from handrig.devices.glove.source import GloveSource
from handrig.loop.warm_up import WarmUp
from handrig.realtime import CpuWake

READ_MARGIN_S = 0.0003  # a read (and its retries) ends this long before the next tick
PERIOD_SMOOTHING = 1.0 / 16.0  # weight of the newest interval in the glove's period estimate
GAP_FACTOR = 4.0  # an interval this many times the estimate is a pause, not a period
FORCED_READ_FACTOR = 4  # no gap fits for this many times read_every ticks: read anyway
ANCHOR_FOLLOW = 1.0 / 16.0  # how fast the glove's grid follows arrivals later than it
JITTER_MARGIN = 1.0  # a gap's read ends this many mean arrival deviations before the frame
FORCED_READ_SHARE = 0.5  # a forced read ends this share of a period after the next frame
CEILING_BURST = 3.0  # ticks the ceiling lets through back to back (after a quiet spell)
CATCH_UP_CREDIT = 2.0  # a catch-up tick leaves the ceiling room for the newest's right after
STALL_PERIODS = 3.0  # the port unread this many frame periods: the host stalled
BACKLOG_QUIET_S = 0.0005  # at the start, the port is read until quiet this long
BACKLOG_MAX_S = 0.05  # ... but no longer than this (a glove that never pauses)
BACKLOG_PUMPS_MAX = 256
POLLS_MAX = 20_000  # a poll window's looks at the port (a look takes about a microsecond)


@dataclass
class Tick:
    """One cycle's timing. ``deadline_s``: the slot the cycle runs in (a fixed tick's
    slot, a glove tick's arrival, a floor tick's deadline); ``now_s``: when it started;
    ``next_s``: when the next cycle is expected (a read must be done by then);
    ``floor_s``: the latest the next cycle may start (the floor rate);
    ``late_s``: how late the cycle started; ``skipped``: whole slots missed before it;
    ``dt_s``: time since the previous cycle started (the slew limit's step);
    ``frame``: a glove frame triggered the cycle; ``catch_up``: the cycle is to take the
    oldest frame kept behind the newest (``take_behind()``; the newest gets a cycle right
    after), and ``behind_s`` is the glove's period: that frame's filter time is this much
    earlier than ``now_s`` for each frame it is behind the newest."""

    index: int = 0
    deadline_s: float = 0.0
    now_s: float = 0.0
    next_s: float = 0.0
    floor_s: float = 0.0
    late_s: float = 0.0
    skipped: int = 0
    dt_s: float = 0.0
    frame: bool = False
    catch_up: bool = False
    behind_s: float = 0.0


def _fd_of(glove: GloveSource) -> int | None:
    """The glove's descriptor when it offers one (to wait on, then pump), else None."""
    fd = glove.fileno()
    return fd if isinstance(fd, int) and fd >= 0 else None


def _readable(fd: int, timeout_s: float) -> bool:
    try:
        ready, _, _ = select.select([fd], [], [], max(0.0, timeout_s))
    except (OSError, ValueError):
        return False  # the port went away: the glove's own read reports it
    return bool(ready)


class Trigger(ABC):
    """What starts each cycle."""

    period_s: float
    """The longest time between cycles (the fixed period, or the floor rate's)."""
    ceiling_waits: int = 0
    """Ticks held back to keep to a ceiling rate."""

    def take_bursts(self) -> int:
        """Glove frames superseded on arrival, sent back to back, since the last call."""
        return 0

    def take_stalled(self) -> int:
        """Glove frames that came one by one while the host read nothing for
        ``STALL_PERIODS`` frame periods or more (a host stall), since the last call."""
        return 0

    @abstractmethod
    def start(self, t0_s: float) -> None:
        """The first tick is due at ``t0_s``."""

    @abstractmethod
    def wait(self, tick: Tick, *, settle: bool = True) -> Tick:
        """Block until the next cycle is due and fill ``tick`` in (returned).
        ``settle=False``: return as soon as the cycle may start and leave what only the
        read schedule needs (``tick.next_s``, the glove's period estimate) to
        :meth:`settle`, which the read schedule calls once the cycle's write is out (or
        the next wait does)."""

    def settle(self, tick: Tick) -> None:  # noqa: B027 - a hook most triggers need not fill
        """Finish the bookkeeping a ``wait(settle=False)`` left (nothing to do here)."""

    def keep_awake(self, wake: CpuWake) -> None:  # noqa: B027 - only a glove trigger uses it
        """Hold ``wake`` around each expected frame (a trigger that expects none: unused)."""

    def read_deadline(self, tick: Tick, now_s: float, reads_due: int, read_every: int,
                      read_s: float) -> float | None:
        """When a present-state read started at ``now_s`` must end, or None for no read
        this cycle. ``reads_due``: cycles since the last read; ``read_s``: how long a
        read is expected to take. Default: in every ``read_every``-th slot (or the first
        slot after it), ending before the next tick; when no slot has had room for one in
        ``FORCED_READ_FACTOR * read_every`` slots (a read longer than a slot), the read is
        taken anyway, ending before the slot after next: the next tick comes late, none
        is skipped."""
        if tick.index % read_every and reads_due <= read_every:
            return None
        end = tick.next_s - READ_MARGIN_S
        if now_s + read_s <= end:
            return end
        if reads_due >= FORCED_READ_FACTOR * read_every:
            return end + self.period_s
        return None

    def delayed(self, tick: Tick, now_s: float) -> bool:
        """Whether the read that just ended at ``now_s`` delayed the next write."""
        return now_s > tick.next_s


class FixedRateTrigger(Trigger):
    """A tick every ``1 / rate_hz`` seconds from the start, on ``clock``.

    ``glove``: stamp its frames as they arrive while
    waiting (see the module docstring); the cycle still runs on the fixed tick.
    """

    def __init__(self, clock: Clock, rate_hz: float, *,
                 glove: GloveSource | None = None) -> None:
        if not rate_hz > 0.0:
            raise ValueError(f"rate_hz must be positive, got {rate_hz}")
        self.clock = clock
        self.period_s = 1.0 / rate_hz
        self.glove = glove
        self._t0 = 0.0
        self._k = 0
        self._last_start = math.nan

    def start(self, t0_s: float) -> None:
        self._t0 = t0_s
        self._k = 0
        self._last_start = math.nan

    def _sleep_until(self, t: float) -> None:
        """Sleep until ``t``, pumping the glove's arrivals meanwhile."""
        clock, glove = self.clock, self.glove
        if glove is not None:
            spin = clock.spin_s if isinstance(clock, MonotonicClock) else 0.0
            while True:
                fd = _fd_of(glove)
                left = t - clock.now() - spin
                if fd is None or left <= 0.0:
                    break
                if _readable(fd, left):
                    glove.pump()
        clock.sleep_until(t)

    def wait(self, tick: Tick, *, settle: bool = True) -> Tick:
        clock, period = self.clock, self.period_s
        deadline = self._t0 + self._k * period
        self._sleep_until(deadline)
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
        tick.floor_s = tick.next_s
        tick.late_s = late
        tick.skipped = skipped
        tick.dt_s = period
        tick.frame = False
        self._last_start = now
        self._k += 1
        return tick


class GloveTrigger(Trigger):
    """A tick per glove frame, between a floor and a ceiling rate (module docstring).

    ``glove``: a source with ``fileno()`` and ``pump()`` (a serial glove read by the
    loop), or with ``next_due_s()`` (a replay); a glove with neither gets the floor
    rate only.

    The glove's period is estimated from the arrivals (:attr:`frame_period_s`, with
    their mean deviation :attr:`frame_jitter_s`); a present-state read is taken only
    when it is expected to end before the next frame (less ``JITTER_MARGIN`` mean
    deviations), and forced (ending before the floor deadline) when no gap fitted for
    ``FORCED_READ_FACTOR * read_every`` cycles.

    ``poll_s`` (``[loop] glove_poll_us``): from ``poll_s`` before the next frame is
    expected (:attr:`predicted_frame_s`) until ``poll_s`` after it, the trigger polls
    the glove's port instead of sleeping on it: a sleeping thread is woken some tens of
    microseconds after the bytes are readable, a polling one finds them at once, at the
    cost of the window's CPU every frame (0: always sleep; the trade-off, measured with
    ``python -m bench felt``, is in docs/measurements.md: the rig file's 150 us takes
    about 1-2 % of a core at 200 Hz and saves 20-100 us of felt latency at p50); left
    out while the CPUs are kept awake (:meth:`keep_awake`): a wake-up is then quick.

    ``warm_up_s`` (``[loop] warm_up_us``): that long before each expected frame the
    trigger runs the cycle's rehearsal (:mod:`handrig.loop.warm_up`, :attr:`warm_up`).

    ``catch_up`` (a glove that keeps the frames behind the newest it never handed out,
    ``has_behind()`` and ``take_behind()``): a frame superseded before its cycle (left
    waiting by a busy loop, or sent together with the next) gets a cycle of its own
    before the newest's, while the ceiling lets that tick and the newest's through
    back to back (a glove faster than the ceiling gets none); counted in
    :attr:`catch_ups`.
    """

    def __init__(self, clock: Clock, glove: GloveSource, *, floor_hz: float, ceiling_hz: float,
                 catch_up: bool = LoopConfig.catch_up, poll_s: float = 0.0,
                 warm_up_s: float = 0.0) -> None:
        if not 0.0 < floor_hz <= ceiling_hz:
            raise ValueError(f"need 0 < floor_hz <= ceiling_hz, got {floor_hz}, {ceiling_hz}")
        if not poll_s >= 0.0:
            raise ValueError(f"need poll_s >= 0, got {poll_s}")
        self.clock = clock
        self.glove = glove
        self.poll_s = poll_s
        self.warm_up = WarmUp(warm_up_s)
        self.polls_found = 0  # frames found by polling in the window (not by a wake-up)
        self.period_s = 1.0 / floor_hz
        self.min_gap_s = 1.0 / ceiling_hz
        self.burst_frames = 0  # frames superseded on arrival by a newer one in the same read
        self.stall_frames = 0  # frames left waiting while the host read nothing (a stall)
        self.frame_period_s = math.nan
        self.frame_jitter_s = 0.0  # mean deviation of the arrivals from the period
        self.ceiling_waits = 0  # frame ticks held back to keep to the ceiling rate
        self.catch_up = bool(catch_up)
        self.catch_ups = 0  # ticks that took the frame behind the newest
        self._credit = 1.0  # ticks the ceiling lets through now (a token bucket)
        self._credit_at = 0.0
        self._k = 0
        self._last_start = 0.0
        self._last_frame = math.nan
        self._anchor = math.nan  # the glove's time grid: an arrival on its early edge
        self._unsettled: Tick | None = None  # a tick whose bookkeeping waits for settle()
        self._unsettled_arrival: float | None = None
        self._drained_s = math.nan  # when a pump last emptied the port
        self._stall_since = math.nan  # the start of the host stall the last pump met

    def start(self, t0_s: float) -> None:
        self._unsettled = self._unsettled_arrival = None
        self._credit, self._credit_at = CEILING_BURST, t0_s  # the bus has been idle
        self._k = 0
        self._last_start = t0_s - self.period_s  # the first floor tick is due at t0_s
        self._last_frame = math.nan
        self._anchor = math.nan
        self.frame_period_s = math.nan
        self.frame_jitter_s = 0.0
        self._take_backlog()

    def _take_backlog(self) -> None:
        """Read what the glove sent before the loop began, until the port has been quiet
        ``BACKLOG_QUIET_S`` (at most ``BACKLOG_MAX_S``): a pty or USB adapter hands a
        backlog over in pieces, and the first cycle then takes the newest frame instead of
        finding the rest of the backlog one cycle later (counted as frames it skipped)."""
        glove, clock = self.glove, self.clock
        fd = _fd_of(glove)
        if fd is None:
            return
        end = clock.now() + BACKLOG_MAX_S
        for _ in range(BACKLOG_PUMPS_MAX):  # bounded under a fake clock too
            if not _readable(fd, BACKLOG_QUIET_S):
                break
            glove.pump()
            if clock.now() >= end:
                break
        self._drained_s = clock.now()

    @property
    def predicted_frame_s(self) -> float:
        """When the next frame is expected (NaN before the period is known): one period
        after the grid's early edge (:meth:`_period_from`), not after the last arrival,
        so a frame that came late does not push the prediction (and the reads fitted
        before it) late too."""
        return self._anchor + self.frame_period_s

    def _new_frame(self) -> bool:
        return self.glove.has_new()

    def _wait_frame(self, until_s: float) -> float | None:
        """Wait for a new frame until ``until_s``; its arrival time, or None if none came."""
        clock, glove = self.clock, self.glove
        if self._new_frame():
            return self._arrival(clock.now())
        fd = _fd_of(glove)
        if fd is not None:
            while True:
                left = until_s - clock.now()
                if left <= 0.0:
                    break
                idle = not _readable(fd, 0.0)  # else bytes were waiting: the loop was busy
                empty_s = clock.now()  # idle: the port was empty now
                if idle and not self._idle_wait(fd, until_s, left):
                    break
                self._pump(idle, empty_s)
                if self._new_frame():
                    return self._arrival(clock.now())
                fd = _fd_of(glove)
                if fd is None:
                    break
            return self._arrival(clock.now()) if self._new_frame() else None
        due = glove.next_due_s()
        if due is not None and due <= until_s:
            clock.sleep_until(due)
            return due
        clock.sleep_until(until_s)
        return None

    def _idle_wait(self, fd: int, until_s: float, left: float) -> bool:
        """Whether bytes come on ``fd`` before ``until_s`` (``left`` from now): after the
        warm-up's rehearsal when one is due, polled within the window, else slept for."""
        at = self.warm_up.at(self.predicted_frame_s, until_s)
        if at is not None:
            now = self.clock.now()
            if at > now:
                if _readable(fd, at - now):
                    return True  # the frame (or bytes of it) came first
                self.warm_up.woke(at, self.clock.now())
            self.warm_up.run(self.predicted_frame_s, self.clock.now())
            left = until_s - self.clock.now()
        if self.poll_s > 0.0 and not self.warm_up.keep_awake.held:  # awake: a wake-up is quick
            return self._polled(fd, until_s)
        return left > 0.0 and _readable(fd, left)

    def _polled(self, fd: int, until_s: float) -> bool:
        """Whether bytes come on ``fd`` before ``until_s`` with a poll window: polled for
        within ``poll_s`` of the predicted frame, slept for otherwise (class docstring)."""
        clock, window = self.clock, self.poll_s
        predicted = self.predicted_frame_s
        now = clock.now()
        if predicted == predicted and now < predicted + window:
            opens = min(predicted - window, until_s)
            if opens > now and _readable(fd, opens - now):
                return True
            closes = min(predicted + window, until_s)
            for _ in range(POLLS_MAX):  # bounded under a clock that does not move too
                if clock.now() >= closes:
                    break
                if _readable(fd, 0.0):
                    self.polls_found += 1
                    return True
        left = until_s - clock.now()
        return left > 0.0 and _readable(fd, left)

    def _next_frame_after(self, now: float) -> float:
        """When the next frame is expected after ``now``: the predicted frame; when it is
        overdue by less than a period, ``now`` (it may come at any moment: no gap to read
        in); when overdue by more (a frame lost, a glove that paused), the grid's next
        slot; infinity before the period is known."""
        predicted, period = self.predicted_frame_s, self.frame_period_s
        if predicted != predicted:
            return math.inf
        if predicted > now:
            return predicted
        if now - predicted < period:
            return now
        return predicted + math.ceil((now - predicted) / period) * period

    def _count(self) -> int:
        newest = self.glove.peek()
        return 0 if newest is None else newest.count

    def _pump(self, idle: bool, empty_s: float = math.nan) -> None:
        """Read the port (the glove stamps what it decodes now). ``idle``: the port was
        seen empty at ``empty_s``, after the loop began waiting; else it was last emptied
        by the previous pump. Only as many frames as the glove's period fits into the
        time since the port was empty can have come one by one; any more were sent
        together (a burst from the glove, counted in ``burst_frames``). When that time
        is ``STALL_PERIODS`` periods or more, the host read nothing for that long (the
        process was stopped or starved inside its wait or its cycle): the frames that
        came one by one meanwhile are the host's backlog (``stall_frames``), not the
        glove's. With the period not yet known, frames together after an empty port
        are a burst."""
        glove = self.glove
        counted = glove.pump_counts  # the glove says how many frames a pump gave
        drained = self._drained_s
        if counted:
            got = glove.pump()
        else:
            before = self._count()
            glove.pump()
            got = self._count() - before
        now = self.clock.now()
        self._drained_s = now
        stall_since, self._stall_since = self._stall_since, math.nan
        since = empty_s if idle else drained
        period = self.frame_period_s
        if not (period == period and period > 0.0 and since == since):
            if idle and got > 1:
                self.burst_frames += got - 1
            return
        if stall_since == stall_since and now - drained < period:
            # the rest of a stall's backlog, which the port (a pty, a USB adapter) handed
            # over in pieces (the first may hold one frame, or none): a glove cannot send
            # these one by one in less than a period after the last pump, but they came
            # one by one in the stall
            since = stall_since
        stalled = now - since >= STALL_PERIODS * period
        if stalled:
            self._stall_since = since
        if got <= 1:
            return
        one_by_one = min(got - 1, int((now - since) / period))
        self.burst_frames += got - 1 - one_by_one
        if stalled:
            self.stall_frames += one_by_one

    def take_bursts(self) -> int:
        """Frames superseded in bursts since the last call (see :meth:`_pump`)."""
        n, self.burst_frames = self.burst_frames, 0
        return n

    def take_stalled(self) -> int:
        """Frames left waiting by a host stall since the last call (see :meth:`_pump`)."""
        n, self.stall_frames = self.stall_frames, 0
        return n

    def keep_awake(self, wake: CpuWake) -> None:
        self.warm_up.keep_awake = wake  # held from the warm-up until the write is out

    def wait(self, tick: Tick, *, settle: bool = True) -> Tick:
        self.warm_up.done()
        if self._unsettled is not None:
            self.settle(self._unsettled)
        clock = self.clock
        floor_at = self._last_start + self.period_s
        arrival: float | None = None
        if self._new_frame():  # read already (the newest, after a catch-up): no waiting
            arrival = self._arrival(clock.now())
        if arrival is None:
            arrival = self._wait_frame(floor_at)
        now = clock.now()
        frame = arrival is not None
        gap = self.min_gap_s
        credit = min(CEILING_BURST, self._credit + (now - self._credit_at) / gap)
        catch_up = False
        if arrival is not None:
            # a frame superseded before its cycle: its own cycle first, when the ceiling
            # lets this tick and the newest's through back to back
            # (not the first tick: the backlog read at the start is history, its newest wins)
            catch_up = (self.catch_up and credit >= CATCH_UP_CREDIT and self._k > 0
                        and self.glove.has_behind())
            if catch_up:
                self.catch_ups += 1
            if credit < 1.0:  # the ceiling: the cycle then takes the newest frame
                self.ceiling_waits += 1
                clock.sleep_until(now + (1.0 - credit) * gap)
                later = clock.now()
                credit = min(CEILING_BURST, credit + (later - now) / gap)
                now = later
            deadline = arrival
        else:
            deadline = floor_at
        self._credit, self._credit_at = max(0.0, credit - 1.0), now
        late = now - floor_at if now > floor_at else 0.0
        skipped = int(late / self.period_s) if late > self.period_s else 0
        tick.index = self._k
        tick.deadline_s = deadline
        tick.now_s = now
        tick.floor_s = now + self.period_s
        tick.next_s = tick.floor_s  # until settled: the period and grid are not updated yet
        tick.late_s = late
        tick.skipped = skipped
        tick.dt_s = min(now - self._last_start, self.period_s)
        tick.frame = frame
        tick.catch_up = catch_up
        period = self.frame_period_s
        tick.behind_s = period if catch_up and period == period else 0.0
        self._last_start = now
        self._k += 1
        self._unsettled, self._unsettled_arrival = tick, arrival
        if settle:
            self.settle(tick)
        return tick

    def settle(self, tick: Tick) -> None:
        """The arrival into the glove's period and grid, and ``tick.next_s`` (the next
        frame expected, at most the floor): off the frame's path with ``wait(settle=False)``."""
        self.warm_up.done()
        if tick is not self._unsettled:
            return
        arrival, self._unsettled = self._unsettled_arrival, None
        if arrival is not None:
            self._period_from(arrival)
        tick.next_s = min(self._next_frame_after(tick.now_s), tick.floor_s)

    def _arrival(self, now: float) -> float:
        """The newest pumped sample's stamp (a replay: its due time), at most ``now``."""
        glove = self.glove
        t = glove.newest_due_s() if _fd_of(glove) is None else None
        if t is None:
            newest = glove.peek()
            t = None if newest is None else newest.host_time_s
        return float(t) if t is not None and t <= now else now

    def _period_from(self, arrival: float) -> None:
        """The period (mean interval), the arrivals' mean deviation from it, and the
        grid's early edge: a glove samples on its own clock and the way to the host only
        ever delays a frame, so the anchor moves to an arrival earlier than the grid
        expects at once and follows later ones only slowly (ANCHOR_FOLLOW)."""
        last, self._last_frame = self._last_frame, arrival
        if last != last:
            self._anchor = arrival
            return
        dt = arrival - last
        if dt <= 0.0:
            return
        est = self.frame_period_s
        if est != est:
            self.frame_period_s = dt
            self._anchor = arrival
        elif dt < GAP_FACTOR * est:
            self.frame_period_s = est + PERIOD_SMOOTHING * (dt - est)
            self.frame_jitter_s += PERIOD_SMOOTHING * (abs(dt - est) - self.frame_jitter_s)
            slots = max(1, round((arrival - self._anchor) / est))
            expected = self._anchor + slots * est
            self._anchor = (arrival if arrival <= expected
                            else expected + ANCHOR_FOLLOW * (arrival - expected))
        else:
            self._anchor = arrival  # after a pause: a new grid

    def read_deadline(self, tick: Tick, now_s: float, reads_due: int, read_every: int,
                      read_s: float) -> float | None:
        self.settle(tick)
        if reads_due < read_every or self.frame_waiting():
            return None
        end = tick.next_s - READ_MARGIN_S - JITTER_MARGIN * self.frame_jitter_s
        if now_s + read_s <= end:
            return end
        if reads_due >= FORCED_READ_FACTOR * read_every:
            # no gap fitted for long: read anyway, delaying the next frame's write but
            # ending early enough (half a period before the frame after it) for that
            # delayed cycle, and a read that overruns its deadline, to be done before the
            # frame after it is due: no frame is skipped for a read. It always has room
            # for the read itself (a glove whose frames come close together must not
            # keep the servos unread), never past the floor.
            period = self.frame_period_s
            latest = (tick.next_s + FORCED_READ_SHARE * period if period == period
                      else tick.floor_s)
            latest = max(latest, now_s + read_s + READ_MARGIN_S)
            return min(latest, tick.floor_s) - READ_MARGIN_S
        return None

    def delayed(self, tick: Tick, now_s: float) -> bool:
        return self.frame_waiting()

    def frame_waiting(self) -> bool:
        """A glove frame (or some of it) is waiting to be read now."""
        glove = self.glove
        if self._new_frame():
            return True
        fd = _fd_of(glove)
        if fd is not None:
            return _readable(fd, 0.0)
        due = glove.next_due_s()
        return due is not None and due <= self.clock.now()
