"""The glove trigger's warm-up, live: a thread plays a glove at 200 Hz into a pipe, and
the trigger runs the rehearsal it was given before each expected frame, once per frame,
while every frame still gets its tick (see handrig/loop/warm_up.py)."""

from __future__ import annotations

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


def test_a_rehearsal_before_each_expected_frame_and_the_frames_still_get_their_ticks(
        pipe_glove: PipeGlove) -> None:
    trig, frames, rehearsals = _run(pipe_glove, LEAD_S)
    # frames the test's own player thread sent together when it was held up (a loaded
    # machine: 55 ticks for 60 frames in a CI run) share a tick, warm-up or not
    assert pipe_glove.count == FRAMES and frames >= FRAMES // 2
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
