"""Glove sources: replay against a fake clock; serial against the pty glove emulator."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import pytest

from firmware_protocol.opengloves import CHANNEL_KEYS
from handrig.clock import FakeClock, MonotonicClock
from handrig.devices.glove import GloveSample, GloveSource, ReplayGlove, SerialGlove
from handrig.devices.glove_recording import GloveRecording, sweep_recording
from handrig.errors import DeviceError
from sim.glove_emulator import GloveEmulator


def wait_for(cond: Callable[[], bool], timeout_s: float = 3.0) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.005)
    return cond()


def collect(glove: GloveSource, n: int, timeout_s: float = 3.0) -> list[GloveSample]:
    got: list[GloveSample] = []

    def more() -> bool:
        s = glove.latest()
        if s is not None:
            got.append(s)
        return len(got) >= n

    wait_for(more, timeout_s)
    return got


def test_replay_hands_out_each_due_sample_once() -> None:
    rec = sweep_recording(0.5, 100.0, 5)
    clock = FakeClock(10.0)
    glove = ReplayGlove(rec, clock)
    with glove:
        s = glove.latest()
        assert s is not None and s.count == 1 and s.host_time_s == 10.0
        np.testing.assert_array_equal(s.raw, rec.raw[0])
        assert glove.latest() is None  # nothing new yet
        clock.advance(0.005)
        assert glove.latest() is None
        clock.advance(0.005)
        s = glove.latest()
        assert s is not None and s.count == 2 and s.host_time_s == pytest.approx(10.01)
        clock.advance(0.05)
        s = glove.latest()
        assert s is not None and s.count == 7
        assert glove.stats().frames_lost == 4 and glove.stats().frames_ok == 3
        assert glove.stats().time_since_last_good_s == pytest.approx(0.0, abs=1e-9)
        clock.advance(1.0)
        s = glove.latest()
        assert s is not None and s.count == len(rec) and glove.finished
        assert glove.latest() is None
        assert glove.stats().time_since_last_good_s > 0.5


def test_replay_loops_and_reports_the_button() -> None:
    rec = sweep_recording(0.1, 100.0, 2, with_imu=False)
    rec = GloveRecording(rec.t_s, rec.raw, np.array([0] * 9 + [1]), rec.channel_names)
    clock = FakeClock()
    glove = ReplayGlove(rec, clock, loop=True)
    glove.start()
    clock.advance(0.09)
    s = glove.latest()
    assert s is not None and s.estop and s.quat is None
    clock.advance(0.01)  # one sample period after the last one: the first again
    s = glove.latest()
    assert s is not None and s.count == 11 and not s.estop
    np.testing.assert_array_equal(s.raw, rec.raw[0])
    assert not glove.finished


@pytest.mark.parametrize("reader", ["thread", "poll"])
def test_serial_frames_from_the_emulator(reader: str) -> None:
    rec = sweep_recording(2.0, 200.0, 5)
    clock = MonotonicClock()
    with GloveEmulator(rec, "frames") as emu, \
            SerialGlove(emu.port_path, "frames", clock=clock,
                        reader=reader) as glove:  # type: ignore[arg-type]
        got = collect(glove, 20)
        assert len(got) >= 20
        s = got[-1]
        assert s.raw.dtype == np.float64 and s.raw.shape == (5,)
        assert s.quat is not None and s.quat.shape == (4,)
        assert s.host_time_s <= clock.now()
        # each sample is a row of the recording, quaternion to Q14 resolution
        i = int(np.argmin(np.abs(rec.raw - s.raw).sum(axis=1)))
        np.testing.assert_array_equal(s.raw, rec.raw[i])
        np.testing.assert_allclose(s.quat, rec.quat_xyzw[i], atol=1 / 16384)
        counts = [g.count for g in got]
        assert counts == sorted(counts) and len(set(counts)) == len(counts)
        st = glove.stats()
        assert st.frames_ok >= 20 and st.errors == 0 and st.failure == ""


def test_serial_counts_garbage_and_corruption_and_keeps_going() -> None:
    rec = sweep_recording(3.0, 200.0, 3)
    with GloveEmulator(rec, "frames", loop=True) as emu, \
            SerialGlove(emu.port_path, "frames", clock=MonotonicClock()) as glove:
        assert len(collect(glove, 5)) == 5
        emu.corrupt_next(3)
        emu.inject_garbage(100)
        assert wait_for(lambda: glove.stats().errors >= 4)
        before = glove.stats().frames_ok
        assert wait_for(lambda: glove.stats().frames_ok >= before + 10)
        st = glove.stats()
        assert st.crc_errors >= 1 and st.resyncs >= 4 and st.garbage_bytes >= 100
        assert st.seq_gaps >= 1 and st.frames_lost >= 3


def test_quiet_glove_returns_none_and_ages() -> None:
    rec = sweep_recording(3.0, 200.0, 3)
    clock = MonotonicClock()
    with GloveEmulator(rec, "frames", loop=True) as emu, \
            SerialGlove(emu.port_path, "frames", clock=clock) as glove:
        assert len(collect(glove, 3)) == 3
        emu.pause()
        time.sleep(0.05)
        glove.latest()
        t0 = time.monotonic()
        assert glove.latest() is None
        assert time.monotonic() - t0 < 0.01  # returns at once, nothing new
        assert wait_for(lambda: glove.stats().time_since_last_good_s > 0.2)
        emu.resume()
        assert len(collect(glove, 3)) == 3


@pytest.mark.parametrize("reader", ["thread", "poll"])
def test_port_that_disappears_is_a_device_error(reader: str) -> None:
    rec = sweep_recording(3.0, 200.0, 3)
    emu = GloveEmulator(rec, "frames", loop=True).start()
    glove = SerialGlove(emu.port_path, "frames", clock=MonotonicClock(), reconnect_s=0,
                        reader=reader)  # type: ignore[arg-type]
    with glove:
        assert len(collect(glove, 3)) == 3
        emu.hang_up()
        assert wait_for(lambda: glove.latest() is None and glove.failure is not None)
        assert emu.port_path in str(glove.failure) and "went away" in str(glove.failure)
        assert glove.stats().failure
        with pytest.raises(DeviceError, match="went away"):
            glove.check()
    emu.close()


def test_opening_a_missing_port_says_what_to_do() -> None:
    glove = SerialGlove("/dev/does-not-exist", "frames", clock=MonotonicClock())
    with pytest.raises(DeviceError, match=r"cannot open glove port /dev/does-not-exist.*--glove"):
        glove.start()


def test_serial_opengloves_lines() -> None:
    rec = sweep_recording(2.0, 200.0, 5, with_imu=False)
    buttons = np.zeros(len(rec), dtype=np.int64)
    buttons[:] = 1 | (1 << 3)  # e-stop and the third button letter (J)
    rec = GloveRecording(rec.t_s, rec.raw, buttons, rec.channel_names)
    with GloveEmulator(rec, "opengloves", estop_letter="N") as emu, \
            SerialGlove(emu.port_path, "opengloves", clock=MonotonicClock(),
                        estop_letter="N") as glove:
        got = collect(glove, 10)
        s = got[-1]
        assert s.raw.shape == (len(CHANNEL_KEYS),) and s.quat is None
        i = int(np.argmin(np.abs(rec.raw - s.raw[:5]).sum(axis=1)))
        np.testing.assert_array_equal(s.raw[:5], rec.raw[i])
        assert s.estop and s.buttons & (1 << 3)
        assert glove.stats().errors == 0


def test_bad_arguments() -> None:
    with pytest.raises(DeviceError, match="format"):
        SerialGlove("/dev/null", "csv", clock=MonotonicClock())  # type: ignore[arg-type]
    with pytest.raises(DeviceError, match="e-stop letter"):
        SerialGlove("/dev/null", "opengloves", clock=MonotonicClock(), estop_letter="Z")


@pytest.mark.parametrize("reader", ["thread", "poll"])
def test_a_replugged_glove_is_picked_up_again(reader: str) -> None:
    rec = sweep_recording(3.0, 200.0, 3)
    first = GloveEmulator(rec, "frames", loop=True).start()
    path = first.port_path
    glove = SerialGlove(path, "frames", clock=MonotonicClock(), reconnect_s=0.05,
                        reader=reader)  # type: ignore[arg-type]
    with glove:
        assert len(collect(glove, 3)) == 3
        first.hang_up()
        assert wait_for(lambda: glove.latest() is None and glove.failure is not None)
        with GloveEmulator(rec, "frames", loop=True) as second:
            if second.port_path != path:
                pytest.skip(f"the kernel gave the new pty another name ({second.port_path})")
            assert len(collect(glove, 3)) == 3
            assert glove.failure is None and glove.stats().reconnects >= 1
            st = glove.stats()
            assert st.disconnects >= 1 and st.last_outage_s > 0.0
            events = glove.drain_events()
            assert any("went away" in e for e in events), events
            assert any(f"glove port {path} is back after" in e and "reconnect 1" in e
                       for e in events), events
            assert glove.drain_events() == []
    first.close()


def _pty_glove(**kw: object) -> tuple[int, SerialGlove]:
    import os
    import tty

    master, slave = os.openpty()
    tty.setraw(master)
    glove = SerialGlove(os.ttyname(slave), "frames", clock=MonotonicClock(), reader="poll",
                        **kw)  # type: ignore[arg-type]
    os.close(slave)
    return master, glove


def _frame(seq: int, n: int) -> bytes:
    from firmware_protocol.glove import GloveFrame, encode_frame

    return encode_frame(GloveFrame(seq, seq * 5000, tuple(100 + 10 * k for k in range(n))))


def test_a_valid_frame_with_another_channel_count_is_counted_and_dropped() -> None:
    import os

    master, glove = _pty_glove()
    with glove:
        os.write(master, _frame(0, 5) + _frame(1, 5))
        assert collect(glove, 1, timeout_s=0.3) == []  # not settled yet (LOCK_FRAMES)
        os.write(master, _frame(2, 5))
        got = collect(glove, 1)
        assert [s.seq for s in got] == [2] and len(got[0].raw) == 5
        os.write(master, _frame(3, 7) + _frame(4, 3))
        assert collect(glove, 1, timeout_s=0.3) == []  # valid CRC, never a sample
        os.write(master, _frame(5, 5))
        assert [s.seq for s in collect(glove, 1)] == [5]
        st = glove.stats()
        assert st.channel_errors == 2 and st.expected_channels == 5
        assert st.decode_errors == 2 and st.crc_errors == 0 and st.frames_ok == 4
    os.close(master)


def test_a_fixed_channel_count_and_a_minimum() -> None:
    import os

    master, glove = _pty_glove(channels=5)
    with glove:
        os.write(master, _frame(0, 5) + _frame(1, 6))
        assert [s.seq for s in collect(glove, 1)] == [0]  # no settling with a fixed count
        assert glove.stats().channel_errors == 1
    os.close(master)
    master, glove = _pty_glove(min_channels=5)
    with glove:  # a glove that settles on fewer channels than the calibration reads
        os.write(master, b"".join(_frame(i, 3) for i in range(5)) + _frame(5, 5))
        assert collect(glove, 1, timeout_s=0.3) == []
        assert glove.stats().channel_errors == 5 and glove.stats().expected_channels == 0
    os.close(master)
    with pytest.raises(DeviceError, match="channels 17"):
        SerialGlove("/dev/null", clock=MonotonicClock(), channels=17)


def test_pump_says_how_many_frames_it_decoded_and_take_does_not_read() -> None:
    import os

    master, glove = _pty_glove(channels=5)
    with glove:
        assert wait_for(lambda: glove.fileno() is not None)
        os.write(master, _frame(0, 5) + _frame(1, 5))
        time.sleep(0.05)
        assert glove.pump() == 2 and glove.pump() == 0
        first = glove.take()
        assert first is not None and first.seq == 1
        os.write(master, _frame(2, 5))
        time.sleep(0.05)
        assert glove.take() is None  # take() never reads the port
        glove.pump()
        second = glove.take()
        assert second is not None and second.seq == 2 and second.count == first.count + 1
        assert abs(second.host_time_s - time.perf_counter()) < 1.0  # stamped now
    os.close(master)


def test_the_frames_behind_the_newest_are_kept_only_while_they_were_never_taken() -> None:
    import os

    from handrig.devices.glove import BEHIND_KEPT

    assert BEHIND_KEPT == 2
    master, glove = _pty_glove(channels=5)
    with glove:
        assert wait_for(lambda: glove.fileno() is not None)
        os.write(master, _frame(0, 5))
        time.sleep(0.02)
        glove.pump()
        assert not glove.has_behind()  # nothing before the first
        assert glove.take() is not None
        os.write(master, b"".join(_frame(k, 5) for k in range(1, 5)))
        time.sleep(0.02)
        glove.pump()
        assert glove.has_behind()
        # the two before the newest, oldest first (the one before them is gone)
        assert [glove.take_behind().seq, glove.take_behind().seq] == [2, 3]
        assert not glove.has_behind() and glove.take_behind() is None  # each taken once
        assert glove.has_new()
        newest = glove.take()
        assert newest is not None and newest.seq == 4
        os.write(master, _frame(5, 5))
        time.sleep(0.02)
        glove.pump()
        assert not glove.has_behind()  # the one before it was taken: nothing to catch up
        assert glove.take().seq == 5
        os.write(master, _frame(6, 5) + _frame(7, 5))
        time.sleep(0.02)
        glove.pump()
        assert glove.take().seq == 7  # the newest taken first: the one behind is gone
        assert not glove.has_behind() and glove.take_behind() is None
    os.close(master)
