"""The glove take writer: what it stores, and what it never does (replace a take)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from handrig.clock import FakeClock
from handrig.devices.glove import GloveSample, ReplayGlove
from handrig.devices.glove_recording import read_glove_recording, sweep_recording
from handrig.errors import DataError
from handrig.outputs.glove_take import GloveTake
from handrig.outputs.recorder import partial_path


def sample(t: float, count: int, raw: tuple[float, ...] = (1.0, 2.0, 3.0),
           quat: tuple[float, ...] | None = (0.0, 0.0, 0.0, 1.0)) -> GloveSample:
    return GloveSample(np.array(raw), None if quat is None else np.array(quat), count % 2,
                       False, count, 0, t, count)


def test_rows_keep_arrival_times_and_same_time_frames_get_a_microsecond(tmp_path: Path) -> None:
    path = tmp_path / "g.csv"
    take = GloveTake(path, channel_names=("a", "b"), rate_hz=100.0, sync=False)
    for k, t in enumerate([10.0, 10.01, 10.01, 10.03]):
        take.tap(sample(t, k + 1, quat=None if k == 2 else (0.0, 0.0, 0.0, 1.0)))
    take(0.0, np.zeros(54))
    assert not path.exists() and partial_path(path).exists()  # written as .partial
    take.close()
    rec = read_glove_recording(path)
    np.testing.assert_allclose(rec.t_s, [0.0, 0.01, 0.010001, 0.03])
    assert rec.channel_names == ("a", "b", "ch2") and rec.rate_hz == 100.0
    assert rec.quat_xyzw is not None and np.isnan(rec.quat_xyzw[2]).all()
    assert rec.buttons.tolist() == [1, 0, 1, 0]
    assert take.status().frames_written == 4 and not partial_path(path).exists()


def test_from_first_output_leaves_the_commissioning_backlog_out(tmp_path: Path) -> None:
    take = GloveTake(tmp_path / "g.csv", sync=False, from_first_output=True)
    for k in range(5):  # read in one go at the loop's start
        take.tap(sample(1.0 + k * 1e-5, k + 1))
    take(0.0, np.zeros(54))  # the first cycle used the newest
    take.tap(sample(1.01, 6))
    take.close()
    rec = read_glove_recording(tmp_path / "g.csv")
    assert len(rec) == 2 and take.backlog_left_out == 4
    np.testing.assert_allclose(rec.t_s, [0.0, 1.01 - (1.0 + 4e-5)])


def test_a_frame_with_another_channel_count_is_dropped_and_counted(tmp_path: Path) -> None:
    take = GloveTake(tmp_path / "g.csv", sync=False)
    take.tap(sample(0.0, 1))
    take.tap(sample(0.01, 2, raw=(1.0, 2.0)))
    take.tap(sample(0.02, 3))
    take.close()
    assert take.frames_written == 2 and take.frames_dropped == 1
    assert len(read_glove_recording(tmp_path / "g.csv")) == 2


def test_a_take_is_never_replaced(tmp_path: Path) -> None:
    old = tmp_path / "g.csv"
    old.write_text("an older take\n")
    with pytest.raises(DataError, match="never replaced"):
        GloveTake(old)
    assert old.read_text() == "an older take\n"
    late = tmp_path / "late.csv"
    take = GloveTake(late, sync=False)
    take.tap(sample(0.0, 1))
    late.write_text("appeared during the run\n")
    line = take.close()
    assert late.read_text() == "appeared during the run\n"
    assert str(partial_path(late)) in line and len(read_glove_recording(partial_path(late)))


def test_a_replayed_glove_taps_what_it_serves(tmp_path: Path) -> None:
    rec = sweep_recording(0.1, 100.0, 5)
    clock = FakeClock()
    glove = ReplayGlove(rec, clock)
    take = GloveTake(tmp_path / "g.csv", sync=False)
    glove.add_tap(take.tap)
    glove.start()
    for _ in range(len(rec)):
        assert glove.latest() is not None
        clock.advance(0.01)
    take.close()
    back = read_glove_recording(tmp_path / "g.csv")
    np.testing.assert_allclose(back.raw, rec.raw)
    np.testing.assert_allclose(back.t_s, rec.t_s, atol=1e-6)


def test_a_full_disk_stops_the_glove_take_and_what_follows_is_counted_dropped(
        tmp_path: Path) -> None:
    import os

    if not Path("/dev/full").exists():
        pytest.skip("needs /dev/full (Linux)")
    take = GloveTake(tmp_path / "g.csv", sync=False, flush_s=60.0)
    os.close(take._fd)
    take._fd = os.open("/dev/full", os.O_WRONLY)  # every write fails: ENOSPC
    take.tap(sample(0.0, 1))
    take(0.0, np.zeros(54))
    take._write_pending()  # the writer's turn: the disk is full
    assert "the glove take stopped" in take.status().stopped_reason
    written = take.frames_written
    for k in range(2, 6):
        take.tap(sample(k * 0.01, k))
    take(0.05, np.zeros(54))
    # nothing is claimed as written: the frame whose write failed and those after the
    # stop are dropped, counted
    assert take.frames_written == written == 0 and take.frames_dropped == 5
    line = take.close()
    assert "stopped" in line and "5 dropped" in line
