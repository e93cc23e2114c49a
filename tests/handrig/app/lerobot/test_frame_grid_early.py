"""A caller that asks faster than the teleoperator's frame grid (``--teleop.fps=30`` with
lerobot-teleoperate's default ``--fps=60``): each call gets the newest pose, the grid
counts those calls apart from a loop that fell behind, and the log says so once, with
the fix, instead of a "fell behind" warning at every call."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from handrig.app.lerobot.glove_stream import FrameGrid
from handrig.app.lerobot.teleop import GloveTeleop
from tests.helpers.lerobot import unfiltered_glove_file, write_ramp_take

FPS = 30.0


def test_calls_faster_than_the_grid_are_counted_early_not_behind() -> None:
    fast = FrameGrid(FPS, max_lag_s=0.1)
    calls = [1.0 + i / (4 * FPS) for i in range(4)]  # four calls a frame
    assert [fast.frame_time(c) for c in calls] == calls
    assert fast.early == 3 and fast.reanchored == 0
    late = FrameGrid(FPS, max_lag_s=0.1)
    for k in range(10):  # 1.5 frames apart: half a frame further behind each call
        late.frame_time(1.0 + 1.5 * k / FPS)
    assert late.reanchored == 1 and late.early == 0 and late.runs == 1


def test_the_teleoperator_says_once_that_it_is_asked_faster_than_its_fps(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    take = write_ramp_take(tmp_path / "take.csv", 400, 0.005, start=1500, step=1)
    glove = GloveTeleop(port=f"replay:{take}", fps=FPS,
                        glove_config=str(unfiltered_glove_file(tmp_path / "glove.toml")))
    glove.connect()
    try:
        with caplog.at_level(logging.WARNING, logger="handrig.app.lerobot.teleop"):
            for _ in range(6):  # no sleep between: far faster than 30 a second
                assert len(glove.action()) == len(glove.names)
    finally:
        glove.disconnect()
    said = [r.getMessage() for r in caplog.records]
    assert len([m for m in said if "asked more often than the 30 fps" in m]) == 1, said
    assert "--teleop.fps" in said[0]
    assert not [m for m in said if "fell more than" in m], said
    assert glove.grid is not None and glove.grid.early == 5
