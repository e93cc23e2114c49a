"""The warm-up's wake-up is asked for early by how late such wake-ups came
(handrig/loop/warm_up.py, ``WarmUp.wake_late_s``, through the glove trigger's wait): on a
virtual machine whose idle CPUs halt, a sleep of a few milliseconds ended 14-176 us late
and left the rehearsal no room before more than half of the frames.

A scripted clock stands for the host: each sleep on the glove's (silent) pipe "wakes"
as late as the script says. Nothing keeps real time: the compute-only lane.
"""

from __future__ import annotations

import pytest

from handrig.clock import Clock
from handrig.loop.trigger import GloveTrigger
from handrig.loop.warm_up import WAKE_LATE_GAIN, WAKE_LATE_MAX_S
from tests.helpers.pipe_glove import PipeGlove


class LateWakeClock(Clock):
    """A clock whose time moves only in ``sleep_until`` and in the trigger's port sleeps
    (patched by the fixture: a real ``select`` on the empty pipe that does not wait, then
    a jump to the wake-up asked for plus ``late_s``)."""

    def __init__(self) -> None:
        self.t = 100.0
        self.late_s: float | None = 0.0  # None: the sleep does not move the clock
        self.asked: list[float] = []

    def now(self) -> float:
        return self.t

    def sleep_until(self, t: float) -> None:
        self.t = max(self.t, t)


@pytest.fixture
def trigger(monkeypatch: pytest.MonkeyPatch):
    import handrig.loop.trigger as trigger_module

    clock = LateWakeClock()
    glove = PipeGlove(clock)  # never sent to: only its descriptor matters here
    real_readable = trigger_module._readable

    def readable(fd: int, timeout_s: float) -> bool:
        got = real_readable(fd, 0.0)
        if timeout_s > 0.0 and not got:  # slept: woke late by the script's lateness
            clock.asked.append(clock.t + timeout_s)
            if clock.late_s is not None:
                clock.t += timeout_s + clock.late_s
        return got

    monkeypatch.setattr(trigger_module, "_readable", readable)
    trig = GloveTrigger(clock, glove, floor_hz=5.0, ceiling_hz=1000.0, warm_up_s=150e-6)
    rehearsals: list[float] = []
    trig.warm_up.rehearse_with(lambda: rehearsals.append(clock.t))
    yield trig, clock, rehearsals
    glove.close()


def _one_frame(trig: GloveTrigger, clock: LateWakeClock, frame_s: float) -> None:
    """The trigger waits (idle) for a frame expected at ``frame_s``; none comes before
    the wait's end, 1 ms after it."""
    trig._anchor, trig.frame_period_s = frame_s - 0.005, 0.005
    trig._idle_wait(trig.glove.fileno(), frame_s + 0.001, frame_s + 0.001 - clock.t)


def test_the_warm_up_wakes_earlier_by_what_it_learnt_and_then_has_room(trigger) -> None:
    trig, clock, rehearsals = trigger
    clock.late_s = 80e-6  # each sleep ends 80 us after the time asked
    assert trig.warm_up.wake_late_s == 0.0
    # the first frame: asked for 150 us before it, woke 70 us before it: no room left
    # for the rehearsal (it needs 100 us: it would delay the frame)
    frame = clock.t + 0.005
    _one_frame(trig, clock, frame)
    assert clock.asked[0] == pytest.approx(frame - 150e-6, abs=1e-9)
    assert rehearsals == []
    assert trig.warm_up.wake_late_s == pytest.approx(WAKE_LATE_GAIN * 80e-6)
    # frame after frame the wake-up is asked for earlier, converging on the lateness
    for _ in range(40):
        clock.t += 0.004
        frame = clock.t + 0.005
        asked_before, learnt = len(clock.asked), trig.warm_up.wake_late_s
        _one_frame(trig, clock, frame)
        assert clock.asked[asked_before] == pytest.approx(frame - 150e-6 - learnt, abs=1e-9)
    assert trig.warm_up.wake_late_s == pytest.approx(80e-6, rel=0.02)
    # woken 150 us before the frame again: the rehearsal ran, with its room
    assert rehearsals and rehearsals[-1] == pytest.approx(frame - 150e-6, abs=3e-6)


def test_a_stalled_wake_up_counts_as_no_later_than_the_bound(trigger) -> None:
    trig, clock, _ = trigger
    clock.late_s = 0.050  # the host stalled 50 ms inside the sleep
    _one_frame(trig, clock, clock.t + 0.005)
    assert trig.warm_up.wake_late_s == pytest.approx(WAKE_LATE_GAIN * WAKE_LATE_MAX_S)


@pytest.mark.parametrize("late_s", [-0.001, None])
def test_a_clock_that_did_not_move_with_the_sleep_teaches_nothing(trigger, late_s) -> None:
    """-1 ms: it "woke" before the time asked; None: it stayed where it was (a test's
    fake clock, not a host's): neither is a lateness."""
    trig, clock, rehearsals = trigger
    clock.late_s = late_s
    frame = clock.t + 0.005
    _one_frame(trig, clock, frame)
    assert trig.warm_up.wake_late_s == 0.0
    assert len(rehearsals) == 1  # the rehearsal still ran (it had its room before the frame)
