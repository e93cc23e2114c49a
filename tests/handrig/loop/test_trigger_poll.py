"""``[loop] glove_poll_us``: the glove trigger polls the port around the expected frame.

A glove sends on its own clock, so once the trigger knows the period it knows when
the next frame is due; with a poll window it polls the port from that long before
until that long after instead of sleeping on it (the trade-off: ``python -m bench
felt``). Here a thread plays a glove at 200 Hz into a pipe; every frame must still
get its tick, and with a window some are found by polling, without one none.
"""

from __future__ import annotations

import pytest

from handrig.clock import MonotonicClock
from handrig.config.rig import LoopConfig
from handrig.errors import ConfigError
from handrig.loop.trigger import GloveTrigger, Tick
from tests.helpers.pipe_glove import PipeGlove, play_and_tick

PERIOD_S = 0.005
FRAMES = 60


def _run(poll_s: float) -> tuple[GloveTrigger, int, int]:
    """The trigger's run over FRAMES frames played at 200 Hz: (trigger, frame ticks,
    frames sent). Played again (three runs at most) while frames share ticks beyond
    what a descheduled thread explains (3), or a window found no frame by polling: on a
    machine loaded by other test runs the player and the waiter are both held off the
    CPU now and then, two frames land in one wake-up, and a waiter that wakes late
    finds each frame already there (a clean-clone CI run beside a busy core: none of 60
    found by polling); a trigger that misses frames or never polls does so in every run."""
    for _ in range(3):
        glove = PipeGlove(MonotonicClock(spin_s=0.0))
        try:
            trig = GloveTrigger(glove.clock, glove, floor_hz=20.0, ceiling_hz=1000.0,
                                poll_s=poll_s)
            frames = play_and_tick(glove, trig, FRAMES, PERIOD_S)
        finally:
            glove.close()
        if frames >= FRAMES - 3 and (trig.polls_found or not poll_s):
            break
    return trig, frames, glove.count


def test_a_poll_window_finds_frames_by_polling_and_every_frame_gets_its_tick() -> None:
    trig, frames, sent = _run(poll_s=0.001)
    assert sent == FRAMES
    assert frames >= FRAMES - 3  # frames merged by a descheduled thread share a tick
    assert trig.polls_found >= 1


def test_without_a_window_the_trigger_sleeps_on_the_port() -> None:
    trig, frames, sent = _run(poll_s=0.0)
    assert sent == FRAMES and frames >= FRAMES - 3
    assert trig.polls_found == 0


def test_the_window_is_checked_in_the_rig_file() -> None:
    LoopConfig(glove_poll_us=150.0).check()
    with pytest.raises(ConfigError, match="glove_poll_us"):
        LoopConfig(glove_poll_us=-1.0).check()
    with pytest.raises(ConfigError, match="glove_poll_us"):
        LoopConfig(glove_poll_us=5000.0).check()


def test_a_poll_window_is_bounded_under_a_clock_that_does_not_move() -> None:
    """A fake clock stands still while the trigger polls: the window still ends (after
    POLLS_MAX looks at the port), and the wait goes on as a sleep to its end."""
    import handrig.loop.trigger as trigger_module
    from handrig.clock import FakeClock
    from handrig.loop.trigger import POLLS_MAX

    clock = FakeClock(10.0)
    glove = PipeGlove(clock)  # type: ignore[arg-type]
    try:
        trig = GloveTrigger(clock, glove, floor_hz=20.0, ceiling_hz=1000.0, poll_s=150e-6)
        trig.start(clock.now())
        for k in range(4):  # frames on a 5 ms grid: the period and the prediction are known
            if k:
                clock.advance(PERIOD_S)
            glove.send()
            trig.wait(Tick())
            glove.latest()
        clock.advance(PERIOD_S)  # now at the predicted frame: the window is open
        assert abs(trig.predicted_frame_s - clock.now()) < 1e-9
        looks: list[float] = []
        real = trigger_module._readable

        def counted(fd: int, timeout_s: float) -> bool:
            looks.append(timeout_s)
            return real(fd, min(timeout_s, 0.01))

        trigger_module._readable = counted
        try:
            assert not trig._polled(glove.fileno(), clock.now() + 0.005)
        finally:
            trigger_module._readable = real
        polls = [t for t in looks if t == 0.0]
        assert len(polls) == POLLS_MAX and looks[-1] > 0.0  # then a sleep to the end
    finally:
        glove.close()
