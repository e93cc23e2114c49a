"""The frame grid of a loop that asks once a frame (handrig/app/lerobot/glove_stream.py):
each call gets its frame's time, k / fps after the run's first call, however late the
call itself comes; a pause starts a new run; a loop too far behind is re-anchored."""

from __future__ import annotations

import pytest

from handrig.app.lerobot.glove_stream import FrameGrid

FPS = 30.0


def test_late_calls_get_their_frames_time_not_their_own() -> None:
    grid = FrameGrid(FPS, max_lag_s=0.1)
    start = 100.0
    # LeRobot's record loop: each iteration 1/fps plus an oversleep, so the calls drift
    # later and later (here 0.4 ms a frame: 36 ms after 90 frames) and jitter
    calls = [start + k / FPS + 0.0004 * k + (0.002 if k % 7 == 3 else 0.0)
             for k in range(90)]
    times = [grid.frame_time(c) for c in calls]
    assert times == [start + k / FPS for k in range(90)]
    assert grid.runs == 1 and grid.reanchored == 0
    assert grid.worst_lag_s == pytest.approx(max(c - t for c, t in zip(calls, times, strict=True)))


def test_a_pause_starts_a_new_run_and_a_loop_too_far_behind_is_re_anchored() -> None:
    grid = FrameGrid(FPS, max_lag_s=0.1)
    for k in range(10):
        grid.frame_time(5.0 + k / FPS)
    # the episode saved, the reset loop begins 2 s later: its first call is frame 0
    assert grid.frame_time(7.5) == 7.5
    assert grid.frame_time(7.5 + 1 / FPS + 0.001) == pytest.approx(7.5 + 1 / FPS)
    assert grid.runs == 2 and grid.reanchored == 0
    # a loop that falls 0.15 s behind (slow iterations, each under the gap that would
    # make it a new run) is re-anchored at the call, and counted
    t, k = 7.5 + 1 / FPS + 0.001, 1
    while True:
        t += 1.5 / FPS
        k += 1
        got = grid.frame_time(t)
        if got == t:
            break
        assert got == pytest.approx(7.5 + k / FPS)
    assert grid.reanchored == 1 and t - (7.5 + k / FPS) > 0.1
    # a caller faster than its fps (asking twice a frame) is not slowed to the grid
    fast = FrameGrid(FPS, max_lag_s=0.1)
    calls = [1.0 + i / (4 * FPS) for i in range(4)]
    assert [fast.frame_time(c) for c in calls] == calls
