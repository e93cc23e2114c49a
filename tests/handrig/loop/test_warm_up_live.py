"""The glove trigger's warm-up, live: a thread plays a glove at 200 Hz into a pipe, and
the trigger runs the rehearsal it was given before each expected frame, once per frame,
while every frame still gets its tick (see handrig/loop/warm_up.py)."""

from __future__ import annotations

from handrig.clock import MonotonicClock
from handrig.loop.trigger import GloveTrigger
from tests.helpers.pipe_glove import PipeGlove, play_and_tick

PERIOD_S = 0.005
FRAMES = 60
LEAD_S = 0.0005


def _run(glove: PipeGlove, warm_up_s: float) -> tuple[GloveTrigger, int, list[tuple[float, int]]]:
    """Play FRAMES frames; returns the trigger, the frame ticks, and each rehearsal's
    (clock time, frames sent by then)."""
    trig = GloveTrigger(glove.clock, glove, floor_hz=20.0, ceiling_hz=1000.0,
                        warm_up_s=warm_up_s)
    rehearsals: list[tuple[float, int]] = []
    trig.warm_up.rehearse_with(lambda: rehearsals.append((glove.clock.now(), glove.count)))
    return trig, play_and_tick(glove, trig, FRAMES, PERIOD_S), rehearsals


def _run_unstarved(glove: PipeGlove) -> tuple[GloveTrigger, int, list[tuple[float, int]]]:
    """:func:`_run` with the warm-up, played again (three runs at most) while fewer than
    half the gaps had a rehearsal: a rehearsal is left out, by design, when the trigger
    wakes for it too late to leave it room, and on a machine loaded by other test runs
    (a clean-clone CI run: 16 in 60 gaps, none in the first 30) that is most wake-ups;
    a trigger that does not rehearse does so in every run."""
    played = glove  # the fixture's first (it closes that one), then one of our own each
    for attempt in range(3):
        if attempt:
            played = PipeGlove(MonotonicClock(spin_s=0.0))
        try:
            trig, frames, rehearsals = _run(played, LEAD_S)
            assert played.count == FRAMES
        finally:
            if played is not glove:
                played.close()
        if len(rehearsals) >= FRAMES // 2:
            break
    return trig, frames, rehearsals


def test_a_rehearsal_before_each_expected_frame_and_the_frames_still_get_their_ticks(
        pipe_glove: PipeGlove) -> None:
    trig, frames, rehearsals = _run_unstarved(pipe_glove)
    # frames the test's own player thread sent together when it was held up (a loaded
    # machine: 55 ticks for 60 frames in a CI run) share a tick, warm-up or not
    assert frames >= FRAMES // 2
    assert trig.warm_up.count == len(rehearsals)
    # once per expected frame at most (the first frames teach the trigger the period)
    assert FRAMES // 2 <= len(rehearsals) <= FRAMES
    # each between two frames, never two for one gap
    seen = [sent for _, sent in rehearsals]
    assert len(set(seen)) == len(seen)


def test_no_warm_up_without_a_lead(pipe_glove: PipeGlove) -> None:
    trig, frames, rehearsals = _run(pipe_glove, 0.0)
    assert pipe_glove.count == FRAMES and frames >= FRAMES // 2
    assert rehearsals == [] and trig.warm_up.count == 0
