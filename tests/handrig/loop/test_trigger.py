"""The triggers on their own: glove frames start cycles, the floor and the ceiling,
arrival stamps, and where present-state reads fit."""

from __future__ import annotations

import math
import os
import time

import numpy as np
import pytest

from handrig.clock import FakeClock, MonotonicClock
from handrig.devices.glove import GloveSource, GloveStats, ReplayGlove
from handrig.devices.glove_recording import GloveRecording
from handrig.loop.trigger import (
    FORCED_READ_FACTOR,
    FORCED_READ_SHARE,
    READ_MARGIN_S,
    FixedRateTrigger,
    GloveTrigger,
    Tick,
)
from tests.helpers.pipe_glove import PipeGlove


def recording(rate_hz: float, n: int) -> GloveRecording:
    t = np.arange(n) / rate_hz
    return GloveRecording(t_s=t, raw=np.full((n, 5), 2000.0),
                          buttons=np.zeros(n, dtype=np.int64),
                          channel_names=tuple(f"c{k}" for k in range(5)), rate_hz=rate_hz)


class QuietGlove(GloveSource):
    """A glove that never sends (nothing to wait on)."""

    def stats(self) -> GloveStats:
        return GloveStats()


def test_a_replay_triggers_a_cycle_when_each_sample_comes_due() -> None:
    clock = FakeClock(10.0)
    glove = ReplayGlove(recording(200.0, 20), clock)
    trig = GloveTrigger(clock, glove, floor_hz=50.0, ceiling_hz=1000.0)
    glove.start()
    trig.start(clock.now())
    tick = Tick()
    starts = []
    for _ in range(10):
        trig.wait(tick)
        assert tick.frame
        sample = glove.latest()
        assert sample is not None and sample.host_time_s == pytest.approx(tick.now_s)
        starts.append(tick.now_s - 10.0)
    np.testing.assert_allclose(starts, np.arange(10) / 200.0, atol=1e-9)
    assert trig.frame_period_s == pytest.approx(0.005)
    assert tick.dt_s == pytest.approx(0.005)
    assert tick.next_s == pytest.approx(tick.now_s + 0.005)  # the predicted next frame


def test_a_silent_glove_gets_the_floor_rate() -> None:
    clock = FakeClock(0.0)
    glove = ReplayGlove(recording(200.0, 3), clock)  # three samples, then silence
    trig = GloveTrigger(clock, glove, floor_hz=100.0, ceiling_hz=1000.0)
    glove.start()
    trig.start(0.0)
    tick = Tick()
    frames = []
    for _ in range(8):
        trig.wait(tick)
        frames.append(tick.frame)
        glove.latest()
    assert frames[:3] == [True, True, True] and not any(frames[3:])
    assert tick.now_s == pytest.approx(0.010 + 5 * 0.010)  # every 10 ms after the last frame
    assert tick.dt_s == pytest.approx(0.010) and tick.skipped == 0


def test_a_frame_wakes_the_loop_at_once_and_is_stamped_on_arrival(pipe_glove) -> None:
    clock = pipe_glove.clock
    trig = GloveTrigger(clock, pipe_glove, floor_hz=10.0, ceiling_hz=5000.0)
    trig.start(clock.now())
    tick = Tick()
    trig.wait(tick)  # the first floor tick is due at the start
    assert not tick.frame
    sent = pipe_glove.send()
    trig.wait(tick)
    assert tick.frame
    sample = pipe_glove.latest()
    assert sample is not None and sent <= sample.host_time_s <= tick.now_s
    assert tick.now_s - sent < 0.05  # woken by the frame, not by the 100 ms floor


def test_no_frame_means_a_floor_tick_after_the_floor_period(pipe_glove) -> None:
    clock = pipe_glove.clock
    trig = GloveTrigger(clock, pipe_glove, floor_hz=50.0, ceiling_hz=1000.0)
    t0 = clock.now()
    trig.start(t0)
    tick = Tick()
    trig.wait(tick)
    trig.wait(tick)
    assert not tick.frame and tick.now_s >= t0 + 0.02 - 1e-4


def test_the_ceiling_holds_a_fast_glove_back_and_the_newest_frame_is_taken(pipe_glove) -> None:
    clock = pipe_glove.clock
    trig = GloveTrigger(clock, pipe_glove, floor_hz=10.0, ceiling_hz=20.0)  # 50 ms gap
    trig.start(clock.now())
    tick = Tick()
    trig.wait(tick)  # the floor tick at the start, then two frames: the start's credit
    for _ in range(2):
        pipe_glove.send()
        trig.wait(tick)
        assert tick.frame and trig.ceiling_waits == 0
        pipe_glove.latest()
    first = tick.now_s
    pipe_glove.send()
    trig.wait(tick)
    assert tick.frame and tick.now_s - first >= 0.05 - 2e-3
    assert trig.ceiling_waits == 1
    pipe_glove.latest()
    start = tick.now_s
    pipe_glove.send()
    time.sleep(0.01)
    pipe_glove.send()  # two frames within one ceiling gap: one cycle, the newest frame
    trig.wait(tick)
    # the bucket keeps an oversleep as credit: the tick before this one came late by
    # `overslept` (a loaded machine), and this gap may be that much shorter
    overslept = max(0.0, (start - first) - 0.05)
    assert tick.now_s - start >= 0.05 - 2e-3 - overslept
    sample = pipe_glove.latest()
    assert sample is not None and sample.count == 5 and pipe_glove.latest() is None


def test_the_ceiling_lets_a_late_frame_and_the_next_through_but_holds_a_fast_glove_to_its_rate(
        pipe_glove) -> None:
    clock = pipe_glove.clock
    trig = GloveTrigger(clock, pipe_glove, floor_hz=5.0, ceiling_hz=20.0)  # 50 ms on average
    trig.start(clock.now())
    tick = Tick()
    trig.wait(tick)  # the floor tick at the start
    pipe_glove.send()
    trig.wait(tick)  # and a frame: the start's credit is used up
    pipe_glove.latest()
    time.sleep(0.15)  # a quiet spell: the ceiling has room for two ticks back to back
    starts = []
    for _ in range(2):  # a frame that came late, then the next one 10 ms after it
        pipe_glove.send()
        trig.wait(tick)
        assert tick.frame and pipe_glove.latest() is not None
        starts.append(tick.now_s)
        time.sleep(0.01)
    assert trig.ceiling_waits == 0 and starts[1] - starts[0] < 0.04
    # a glove far faster than the ceiling: held back to 20 Hz, each cycle the newest frame
    t0 = clock.now()
    cycles = 0
    while clock.now() - t0 < 0.5:
        pipe_glove.send()
        time.sleep(0.005)
        if trig.frame_waiting():
            trig.wait(tick)
            sample = pipe_glove.latest()
            assert sample is not None and sample.count == pipe_glove.count
            cycles += 1
    assert trig.ceiling_waits > 0
    assert cycles <= 0.5 * 20.0 + 2  # the rate, and at most the one tick of credit left


def test_the_fixed_trigger_stamps_frames_as_they_arrive(pipe_glove) -> None:
    clock = pipe_glove.clock
    trig = FixedRateTrigger(clock, 20.0, glove=pipe_glove)  # 50 ms ticks
    trig.start(clock.now())
    tick = Tick()
    trig.wait(tick)
    sent = pipe_glove.send()
    trig.wait(tick)  # the cycle still waits for its tick
    assert tick.now_s - sent > 0.03
    sample = pipe_glove.latest()
    assert sample is not None and sample.host_time_s - sent < 0.02  # stamped on arrival


def test_reads_go_into_the_gap_before_the_next_frame_or_wait_for_one() -> None:
    clock = FakeClock(0.0)
    glove = ReplayGlove(recording(200.0, 100), clock)
    trig = GloveTrigger(clock, glove, floor_hz=100.0, ceiling_hz=1000.0)
    glove.start()
    trig.start(0.0)
    tick = Tick()
    for _ in range(5):
        trig.wait(tick)
        glove.latest()
    now = tick.now_s + 0.0005
    end = trig.read_deadline(tick, now, reads_due=4, read_every=4, read_s=0.002)
    assert end == pytest.approx(tick.next_s - READ_MARGIN_S)
    assert trig.read_deadline(tick, now, reads_due=3, read_every=4, read_s=0.002) is None
    assert trig.read_deadline(tick, now, reads_due=4, read_every=4, read_s=0.0045) is None
    forced = trig.read_deadline(tick, now, reads_due=4 * FORCED_READ_FACTOR, read_every=4,
                                read_s=0.0045)
    # forced: the next frame's write waits, but the read ends half a period before the
    # frame after it, so the delayed cycle is done before that frame comes
    assert forced == pytest.approx(
        tick.next_s + FORCED_READ_SHARE * trig.frame_period_s - READ_MARGIN_S)
    assert forced <= tick.floor_s - READ_MARGIN_S
    # a read longer than that still gets room for itself, never past the floor
    long_read = trig.read_deadline(tick, now, reads_due=4 * FORCED_READ_FACTOR,
                                   read_every=4, read_s=0.008)
    assert long_read == pytest.approx(now + 0.008)
    assert trig.read_deadline(tick, now, reads_due=4 * FORCED_READ_FACTOR, read_every=4,
                              read_s=0.02) == pytest.approx(tick.floor_s - READ_MARGIN_S)
    assert not trig.delayed(tick, now)
    clock.advance(0.006)  # the next sample came due while the read was on the wire
    assert trig.delayed(tick, clock.now())


def test_the_fixed_trigger_reads_every_read_every_slots_as_before() -> None:
    clock = FakeClock(0.0)
    trig = FixedRateTrigger(clock, 200.0)
    trig.start(0.0)
    tick = Tick()
    due = []
    for _ in range(8):
        trig.wait(tick)
        due.append(trig.read_deadline(tick, tick.now_s, 1, 4, 0.0) is not None)
    assert due == [True, False, False, False, True, False, False, False]


def test_frames_sent_back_to_back_count_as_a_burst_not_as_frames_the_loop_skipped(
        pipe_glove) -> None:
    clock = pipe_glove.clock
    trig = GloveTrigger(clock, pipe_glove, floor_hz=20.0, ceiling_hz=5000.0)
    trig.start(clock.now())
    tick = Tick()
    trig.wait(tick)
    import threading
    timer = threading.Timer(0.005, lambda: pipe_glove.send(3))  # while the loop waits
    timer.start()
    trig.wait(tick)
    timer.join()
    assert tick.frame and trig.take_bursts() == 2 and trig.take_bursts() == 0
    pipe_glove.latest()
    pipe_glove.send(2)  # while the loop is busy: waiting when it comes back
    time.sleep(0.002)
    trig.wait(tick)
    assert tick.frame and trig.take_bursts() == 0  # the loop's own lateness


class CountingPipeGlove(PipeGlove):
    """A :class:`PipeGlove` whose pump says how many frames it decoded (as SerialGlove)."""

    pump_counts = True

    def pump(self) -> int:
        before = self.count
        super().pump()
        return self.count - before


def test_frames_waiting_for_a_busy_loop_are_a_burst_beyond_what_the_period_fits() -> None:
    glove = CountingPipeGlove(MonotonicClock(spin_s=0.0))
    try:
        clock = glove.clock
        trig = GloveTrigger(clock, glove, floor_hz=5.0, ceiling_hz=5000.0)
        trig.start(clock.now())
        tick = Tick()
        trig.wait(tick)
        for _ in range(6):  # a 50 Hz glove: the trigger learns its period
            time.sleep(0.02)
            glove.send()
            trig.wait(tick)
            glove.latest()
        assert trig.frame_period_s == pytest.approx(0.02, rel=0.3)
        trig.take_bursts()
        glove.send(3)  # three frames at once while the loop is busy for 3 ms
        time.sleep(0.003)
        trig.wait(tick)
        assert tick.frame and glove.latest().count == glove.count
        assert trig.take_bursts() == 2  # a 20 ms glove cannot send three in 3 ms one by one
        for _ in range(3):  # three frames 20 ms apart while the loop is busy for ~60 ms
            glove.send()
            time.sleep(0.02)
        trig.wait(tick)
        assert tick.frame and trig.take_bursts() == 0  # the loop's own lateness
    finally:
        glove.close()


def test_the_fixed_trigger_reads_in_a_later_slot_or_forced_over_two_when_one_is_too_short(
        ) -> None:
    clock = FakeClock(0.0)
    trig = FixedRateTrigger(clock, 500.0)  # 2 ms slots
    trig.start(0.0)
    tick = Tick()
    trig.wait(tick)
    # a read of 1 ms fits the slot it starts in
    assert trig.read_deadline(tick, tick.now_s, 4, 4, 0.001) == pytest.approx(
        tick.next_s - READ_MARGIN_S)
    # a read of 3 ms never fits one slot: skipped, then forced ending before the slot
    # after next (the next tick comes late, no slot is skipped)
    assert trig.read_deadline(tick, tick.now_s, 5, 4, 0.003) is None
    forced = trig.read_deadline(tick, tick.now_s, 4 * FORCED_READ_FACTOR, 4, 0.003)
    assert forced == pytest.approx(tick.next_s + 0.002 - READ_MARGIN_S)


def test_the_prediction_keeps_to_the_gloves_grid_when_frames_come_late() -> None:
    clock = FakeClock(0.0)
    trig = GloveTrigger(clock, QuietGlove(), floor_hz=50.0, ceiling_hz=1000.0)
    trig.start(0.0)
    late = {3: 0.0012, 4: 0.0008, 7: 0.0015}  # frames delayed on the way, never early
    for k in range(10):
        trig._period_from(0.005 * k + late.get(k, 0.0))
    # the late frames pull neither the period nor the next frame's prediction late by
    # more than a sliver: the next frame is expected on the grid, at 50 ms
    assert trig.frame_period_s == pytest.approx(0.005, abs=2e-4)
    assert trig.predicted_frame_s == pytest.approx(0.050, abs=2e-4)
    trig._period_from(0.0498)  # one earlier than the grid: the grid moves to it at once
    assert trig.predicted_frame_s == pytest.approx(0.0548, abs=2e-4)


def test_an_overdue_frame_leaves_no_gap_to_read_in_and_a_lost_one_the_next_slot() -> None:
    clock = FakeClock(0.0)
    trig = GloveTrigger(clock, QuietGlove(), floor_hz=50.0, ceiling_hz=1000.0)
    trig.start(0.0)
    assert trig._next_frame_after(0.0) == math.inf  # no period yet
    for k in range(6):
        trig._period_from(0.005 * k)
    predicted = trig.predicted_frame_s
    assert predicted == pytest.approx(0.030)
    assert trig._next_frame_after(0.028) == pytest.approx(predicted)
    assert trig._next_frame_after(0.032) == pytest.approx(0.032)  # late: any moment now
    assert trig._next_frame_after(0.0423) == pytest.approx(0.045)  # lost: the grid's slot


def test_the_start_reads_the_whole_backlog_so_the_first_cycle_takes_the_newest_frame() -> None:
    """A glove streaming before the loop starts leaves more than one read's worth on the
    port (a pty hands it over in pieces): all of it is read at the start, so the cycle
    after the first does not find the rest and count it as frames the loop skipped."""
    glove = CountingPipeGlove(MonotonicClock(spin_s=0.0))
    try:
        clock = glove.clock
        glove.send(6000)  # one pump reads at most 4096
        trig = GloveTrigger(clock, glove, floor_hz=5.0, ceiling_hz=5000.0)
        trig.start(clock.now())
        assert glove.count == 6000 and glove.pumps >= 2
        tick = Tick()
        trig.wait(tick)
        assert tick.frame and glove.latest().count == 6000
        glove.send()
        trig.wait(tick)
        assert tick.frame and glove.latest().count == 6001  # the next one, none between
    finally:
        glove.close()


def _pty_frames_glove():
    """A real SerialGlove (poll reader, handrig frames) on a pty, and the pty's master."""
    import tty

    from handrig.devices.glove import SerialGlove

    master, slave = os.openpty()
    tty.setraw(master)
    glove = SerialGlove(os.ttyname(slave), "frames", clock=MonotonicClock(spin_s=0.0),
                        reader="poll", channels=5)
    os.close(slave)
    glove.start()
    seq = [0]

    def send(n: int = 1) -> None:
        from firmware_protocol.glove import GloveFrame, encode_frame

        data = b""
        for _ in range(n):
            data += encode_frame(GloveFrame(seq[0], seq[0] * 20_000, (2000,) * 5))
            seq[0] += 1
        os.write(master, data)
    return master, glove, send


def _on_the_port(glove, n_frames: int, timeout_s: float = 2.0) -> None:
    """Wait until ``n_frames`` frames' bytes wait on the glove's port (FIONREAD). A pty
    hands each write to the reader's side later, on a kernel worker: on a loaded host two
    frames written one after the other can otherwise be read one pump apart."""
    import fcntl
    import struct
    import termios

    from firmware_protocol.glove import GloveFrame, encode_frame

    size = len(encode_frame(GloveFrame(0, 0, (2000,) * 5)))
    end = time.monotonic() + timeout_s
    while True:
        waiting = struct.unpack("i", fcntl.ioctl(glove.fileno(), termios.FIONREAD, b"\0" * 4))[0]
        if waiting >= n_frames * size:
            return
        assert time.monotonic() < end, f"{waiting} bytes on the port, {n_frames * size} sent"
        time.sleep(0.0005)


@pytest.mark.parametrize("catch_up", [True, False])
def test_a_frame_the_loop_was_late_for_gets_its_cycle_just_before_the_newest(catch_up) -> None:
    """Two frames one period apart came while the loop was busy: with catch_up the first
    tick takes the older one (filtered a period earlier) and the next tick follows at
    once with the newest; without, the newest only. Two frames the glove sent together
    are caught up the same way; a late pair when the ceiling's burst is spent is not."""
    master, glove, send = _pty_frames_glove()
    try:
        clock = glove.clock
        trig = GloveTrigger(clock, glove, floor_hz=5.0, ceiling_hz=60.0, catch_up=catch_up)
        trig.start(clock.now())
        tick = Tick()
        trig.wait(tick)  # the first floor tick is due at the start
        sent_at = []
        for _ in range(8):  # a 50 Hz glove: the period is learnt, the ceiling stays full
            time.sleep(0.02)
            send()
            sent_at.append(time.monotonic())
            trig.wait(tick)
            assert tick.frame and not tick.catch_up and glove.take() is not None
        # the period learnt is the one the frames came at (20 ms asked; a loaded host's
        # sleeps last longer)
        sent_period = float(np.mean(np.diff(sent_at)))
        assert trig.frame_period_s == pytest.approx(sent_period, rel=0.3)
        send()  # the loop is busy for two periods: a frame, then the next one
        time.sleep(0.02)
        send()
        _on_the_port(glove, 2)
        period = trig.frame_period_s
        trig.wait(tick)
        assert tick.frame and tick.catch_up is catch_up
        if catch_up:
            behind = glove.take_behind()
            # its filter time: one period of the glove, as learnt, before the newest's
            assert behind is not None and tick.behind_s == period
            begun = clock.now()
            trig.wait(tick)  # the newest is there: its tick comes at once
            assert tick.frame and not tick.catch_up and clock.now() - begun < 0.005
            newest = glove.take()
            assert newest is not None and newest.count == behind.count + 1
            assert trig.catch_ups == 1
            # late again at once (two frames one after the other, the newest's tick just
            # gone): the ceiling (60 Hz) has no room for a catch-up, the newest wins. The
            # ceiling refills one tick every 1/60 s: a host that took longer than that
            # between the two ticks (seen on their own times) gave it that room after all
            newest_tick = tick.now_s
            send()
            send()
            _on_the_port(glove, 2)
            trig.wait(tick)
            assert tick.frame
            extra = int(tick.catch_up)
            if tick.catch_up:
                assert tick.now_s - newest_tick >= trig.min_gap_s, tick.now_s - newest_tick
                assert glove.take_behind() is not None
                trig.wait(tick)
            assert glove.take() is not None
        else:
            assert glove.take() is not None and trig.catch_ups == 0
            extra = 0
        time.sleep(0.1)  # the ceiling fills up again
        trig.take_bursts()
        import threading
        timer = threading.Timer(0.005, lambda: send(2))  # sent together, the loop waiting
        timer.start()
        trig.wait(tick)
        timer.join()
        assert tick.frame and tick.catch_up is catch_up
        assert trig.take_bursts() == 1  # came together (the cycle counts it lost or not)
        if catch_up:
            assert glove.take_behind() is not None
            trig.wait(tick)
            assert tick.frame and not tick.catch_up and trig.take_bursts() == 0
        assert glove.take() is not None
        assert trig.catch_ups == (2 + extra if catch_up else 0)
    finally:
        glove.close()
        os.close(master)


def test_a_replay_sample_the_loop_was_late_for_gets_its_cycle_before_the_newest() -> None:
    clock = FakeClock(10.0)
    glove = ReplayGlove(recording(200.0, 40), clock)
    trig = GloveTrigger(clock, glove, floor_hz=50.0, ceiling_hz=1000.0, catch_up=True)
    glove.start()
    trig.start(clock.now())
    tick = Tick()
    for _ in range(5):
        trig.wait(tick)
        assert tick.frame and not tick.catch_up and glove.latest() is not None
    last = glove.peek().count
    clock.advance(0.012)  # the loop was busy: two samples came due meanwhile
    trig.wait(tick)
    assert tick.catch_up and tick.behind_s == pytest.approx(0.005)
    behind = glove.take_behind()
    assert behind is not None and behind.count == last + 1
    assert behind.host_time_s == pytest.approx(10.0 + last * 0.005)  # when it came due
    trig.wait(tick)
    assert tick.frame and not tick.catch_up
    assert glove.latest().count == last + 2 and glove.stats().frames_lost == 0
    clock.advance(0.022)  # four due: the two behind the newest are caught up, one lost
    for k in (4, 5):
        trig.wait(tick)
        assert tick.catch_up and glove.take_behind().count == last + k
    trig.wait(tick)
    assert not tick.catch_up
    assert glove.latest().count == last + 6 and glove.stats().frames_lost == 1


def test_after_a_catch_up_the_newest_is_not_held_back() -> None:
    """The newest frame is read already when its tick is asked for: it goes at once, not
    at the next predicted frame or the floor."""
    master, glove, send = _pty_frames_glove()
    try:
        clock = glove.clock
        trig = GloveTrigger(clock, glove, floor_hz=5.0, ceiling_hz=1000.0, catch_up=True)
        trig.start(clock.now())
        tick = Tick()
        trig.wait(tick)
        for _ in range(8):
            time.sleep(0.02)
            send()
            trig.wait(tick)
            glove.take()
        send()
        time.sleep(0.02)
        send()
        _on_the_port(glove, 2)
        trig.wait(tick)
        assert tick.catch_up and glove.take_behind() is not None
        begun = clock.now()
        trig.wait(tick)
        assert tick.frame and clock.now() - begun < 0.005
        assert glove.take() is not None
    finally:
        glove.close()
        os.close(master)


def test_the_backlog_at_the_start_is_not_caught_up() -> None:
    """Frames the glove sent before the loop began are history: the first cycle takes the
    newest of them, not the ones before it."""
    master, glove, send = _pty_frames_glove()
    try:
        clock = glove.clock
        send(5)
        time.sleep(0.02)
        trig = GloveTrigger(clock, glove, floor_hz=5.0, ceiling_hz=1000.0, catch_up=True)
        trig.start(clock.now())
        assert glove.has_behind()  # the glove kept two of the backlog behind the newest
        tick = Tick()
        trig.wait(tick)
        assert tick.frame and not tick.catch_up and trig.catch_ups == 0
        assert glove.take().seq == 4 and not glove.has_behind()
    finally:
        glove.close()
        os.close(master)
