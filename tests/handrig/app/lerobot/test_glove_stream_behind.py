"""The teleoperator's glove thread held up (a busy machine starves it): a frame asked for
meanwhile still gets the sample of its time once the thread runs again, and samples the
glove superseded meanwhile are counted, not passed over in silence
(handrig/app/lerobot/glove_stream.py; no LeRobot needed). The thread is held up inside
its own pipeline call, deterministically: no luck in the timing."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np

from handrig.app.lerobot.glove_stream import GloveStream
from handrig.clock import MonotonicClock
from handrig.devices.glove.replay import ReplayGlove
from handrig.devices.glove.source import GloveSample
from handrig.devices.glove_recording import read_glove_recording
from tests.helpers.lerobot import write_ramp_take

ROW_S = 0.05  # 20 rows a second: a hold-up of 0.15 s keeps every row behind the newest
START, STEP = 1500, 10  # the ramp's channel: row i reads START + STEP * i
MCP = 3  # the ramp's column among the take's channels


class HeldUp:
    """The stream's pipeline (the raw counts), held up ``hold_s`` when it reaches row
    ``row``: the time that row came due is kept and ``reached`` set first."""

    def __init__(self, row: int, hold_s: float) -> None:
        self.row, self.hold_s = row, hold_s
        self.reached = threading.Event()
        self.due_s = float("nan")
        self.counts: list[int] = []

    def __call__(self, sample: GloveSample) -> np.ndarray:
        self.counts.append(sample.count)
        if sample.count == self.row + 1 and not self.reached.is_set():
            self.due_s = sample.host_time_s
            self.reached.set()
            time.sleep(self.hold_s)
        return np.array(sample.raw, dtype=np.float64)


def _stream(tmp_path: Path, held: HeldUp) -> GloveStream:
    take = write_ramp_take(tmp_path / "ramp.csv", 200, ROW_S, start=START, step=STEP)
    clock = MonotonicClock()
    return GloveStream(ReplayGlove(read_glove_recording(take), clock), held, clock)


def test_a_frame_asked_while_the_thread_is_held_up_gets_its_own_row(tmp_path: Path) -> None:
    # held up 0.15 s: longer than the 50 ms pose_at waited before (it then answered with
    # the row before this frame's, and said nothing), shorter than CATCH_UP_S
    held = HeldUp(row=10, hold_s=0.15)
    with _stream(tmp_path, held) as stream:
        assert held.reached.wait(30.0), "the take never reached row 10"
        got = stream.pose_at(held.due_s + 0.001)  # asked while the thread is held up
        assert got is not None
        assert got[0] == held.due_s and got[1][MCP] == START + STEP * 10, got
        assert stream.late_answers == 0 and stream.lost == 0


def test_samples_the_glove_superseded_while_the_thread_was_held_up_are_counted(
        tmp_path: Path) -> None:
    held = HeldUp(row=10, hold_s=0.4)  # 8 rows come due; the glove keeps 2 behind the newest
    with _stream(tmp_path, held) as stream:
        assert held.reached.wait(30.0), "the take never reached row 10"
        end = time.monotonic() + 30.0
        while len(held.counts) < 20:
            assert time.monotonic() < end, held.counts
            time.sleep(0.01)
        counts = list(held.counts)
        lost = stream.lost
    missing = counts[-1] - counts[0] + 1 - len(set(counts))
    assert missing > 0, counts  # rows went by unseen (the glove keeps only 2 behind)
    assert lost >= missing, (lost, counts)  # ... and every one was counted
