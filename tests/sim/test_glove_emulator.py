"""The glove emulator: real bytes on a real pty, its fault switches, and `handrig sim-glove`."""

from __future__ import annotations

import contextlib
import os
import re
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from firmware_protocol.glove import FrameDecoder, GloveFrame
from firmware_protocol.opengloves import LineDecoder
from handrig.devices.glove_recording import GloveRecording, sweep_recording, write_glove_recording
from handrig.errors import DataError
from sim.glove_emulator import GloveEmulator


def _ctrl_c_as_from_a_shell() -> None:
    """A child's Ctrl-C as a shell starts it: SIGINT at its default and not blocked,
    whatever disposition this test process may have inherited."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})

def read_for(fd: int, seconds: float) -> bytes:
    out = bytearray()
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        ready, _, _ = select.select([fd], [], [], 0.02)
        if ready:
            try:
                out += os.read(fd, 4096)
            except OSError:
                break
    return bytes(out)


def open_port(path: str) -> int:
    return os.open(path, os.O_RDONLY | os.O_NOCTTY)


def test_streams_the_recording_in_order() -> None:
    rec = sweep_recording(0.2, 100.0, 5)
    with GloveEmulator(rec, "frames") as emu:
        fd = open_port(emu.port_path)
        try:
            assert emu.done.wait(2.0)
            data = read_for(fd, 0.1)
        finally:
            os.close(fd)
    dec = FrameDecoder()
    frames: list[GloveFrame] = dec.feed(data)
    assert [f.seq for f in frames] == list(range(len(rec)))
    assert [f.channels for f in frames] == [tuple(int(v) for v in r) for r in rec.raw]
    assert dec.stats.errors == 0
    # timestamps follow the recording (microseconds)
    assert [f.timestamp_us for f in frames] == [round(t * 1e6) for t in rec.t_s]


def test_fixed_rate_resamples_the_recording() -> None:
    rec = sweep_recording(0.2, 50.0, 2)
    with GloveEmulator(rec, "frames", rate_hz=200.0) as emu:
        fd = open_port(emu.port_path)
        try:
            assert emu.done.wait(2.0)
            frames = FrameDecoder().feed(read_for(fd, 0.1))
        finally:
            os.close(fd)
    assert len(frames) == 200 * 0.18 + 1  # samples due at k/200 s up to the last (0.18 s)
    assert frames[4].channels == tuple(int(v) for v in rec.raw[1])  # 0.02 s -> row 1


def test_fault_switches() -> None:
    rec = sweep_recording(2.0, 200.0, 3)
    with GloveEmulator(rec, "frames", loop=True) as emu:
        fd = open_port(emu.port_path)
        try:
            data = read_for(fd, 0.05)
            emu.corrupt_next(4)
            data += read_for(fd, 0.1)
            emu.inject_garbage(20, with_zeros=False)
            data += read_for(fd, 0.1)
            emu.pause()
            time.sleep(0.03)
            read_for(fd, 0.02)
            assert read_for(fd, 0.1) == b""  # paused: silent
            emu.resume()
            assert read_for(fd, 0.1)
            emu.hang_up()
            ready, _, _ = select.select([fd], [], [], 1.0)
            assert ready
            with contextlib.suppress(OSError):  # an I/O error, depending on the kernel
                assert os.read(fd, 10) == b""  # or end of file
        finally:
            os.close(fd)
    dec = FrameDecoder()
    dec.feed(b"\x00" + data)
    # 4 corrupted frames; the zero-free garbage merges with the next frame and spoils it
    s = dec.stats
    assert s.crc_errors >= 3 and s.errors == 5 and s.frames_ok > 20
    assert s.garbage_bytes >= 20 + 5 * 20
    assert (s.seq_gaps, s.frames_lost) == (2, 5)


def test_opengloves_lines_on_the_wire() -> None:
    rec = sweep_recording(0.1, 100.0, 5)
    with GloveEmulator(rec, "opengloves", analog_max=1023) as emu:
        fd = open_port(emu.port_path)
        try:
            assert emu.done.wait(2.0)
            data = read_for(fd, 0.05)
        finally:
            os.close(fd)
    lines = LineDecoder(1023).feed(data)
    assert len(lines) == len(rec)
    assert lines[0].fingers == tuple(int(v) for v in np.clip(rec.raw[0], 0, 1023))
    assert data.endswith(b"\n") and data.startswith(b"A")


def test_bad_input_is_refused() -> None:
    rec = sweep_recording(0.1, 100.0, 3)
    with pytest.raises(DataError, match="5 finger channels"):
        GloveEmulator(rec, "opengloves")
    with pytest.raises(DataError, match="rate"):
        GloveEmulator(rec, "frames", rate_hz=0.1)
    with pytest.raises(DataError, match="e-stop letter"):
        GloveEmulator(sweep_recording(0.1, 100.0, 5), "opengloves", estop_letter="Z")
    with pytest.raises(DataError, match="at most 16 channels"):
        GloveEmulator(sweep_recording(0.1, 100.0, 17), "frames")


def test_sim_glove_command_prints_the_port_first(tmp_path: Path) -> None:
    p = tmp_path / "g.csv"
    write_glove_recording(p, sweep_recording(0.3, 100.0, 5))
    proc = subprocess.Popen(
        [sys.executable, "-m", "handrig.cli", "sim-glove", str(p)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        cwd=Path(__file__).resolve().parents[2], preexec_fn=_ctrl_c_as_from_a_shell,
    )
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()
        assert first.startswith("port: /dev/pts/")
        fd = open_port(first.split(": ", 1)[1].strip())
        try:
            data = read_for(fd, 0.6)
        finally:
            os.close(fd)
        out, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert "sent 30 frames" in out
    assert len(FrameDecoder().feed(data)) >= 10


def test_sim_glove_command_bad_file(tmp_path: Path) -> None:
    from handrig.cli import main

    bad = tmp_path / "bad.csv"
    bad.write_text("nope\n")
    assert main(["sim-glove", str(bad)]) == 2


def test_play_switches_recording_mid_stream_and_loops_from_a_point() -> None:
    def constant(value: int, seconds: float, channels: int = 3) -> GloveRecording:
        n = round(seconds * 100)
        raw = np.full((n, channels), float(value))
        return GloveRecording(np.arange(n) / 100.0, raw, np.zeros(n, dtype=np.int64),
                              tuple(f"ch{i}" for i in range(channels)), None, 100.0)

    first = constant(100, 0.1)
    with GloveEmulator(first, "frames", rate_hz=100.0) as emu:
        fd = open_port(emu.port_path)
        try:
            assert emu.done.wait(2.0)  # the first recording ran out: silent, port open
            data = read_for(fd, 0.05)
            # a move (0.1 s at 200) and a hold (700) looped from 0.1 s: never 200 again
            move = constant(200, 0.1)
            hold = constant(700, 0.1)
            both = GloveRecording(np.arange(20) / 100.0, np.vstack([move.raw, hold.raw]),
                                  np.zeros(20, dtype=np.int64), move.channel_names, None, 100.0)
            emu.play(both, loop=True, loop_from_s=0.1)
            assert not emu.done.is_set()
            data += read_for(fd, 0.5)
        finally:
            os.close(fd)
    frames = FrameDecoder().feed(data)
    values = [f.channels[0] for f in frames]
    assert values[:10] == [100] * 10
    rest = values[10:]
    assert rest[:10] == [200] * 10 and set(rest[10:]) == {700} and len(rest) > 35
    stamps = [f.timestamp_us for f in frames]
    assert np.all(np.diff(stamps) > 0)  # the glove's clock
    with pytest.raises(DataError, match="loop_from_s"):
        GloveEmulator(first, "frames", loop=True, loop_from_s=5.0)


def test_sim_glove_calibration_on_a_timer_announces_each_pose() -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "handrig.cli", "sim-glove", "--calibration", "--pose-s", "0.8",
         "--transition-s", "0.2"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        cwd=Path(__file__).resolve().parents[2], preexec_fn=_ctrl_c_as_from_a_shell,
    )
    lines: list[str] = []
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()
        assert first.startswith("port: /dev/pts/")
        fd = open_port(first.split(": ", 1)[1].strip())
        try:
            while sum(line.startswith("pose 1/4 open") for line in lines) < 2:
                lines.append(proc.stdout.readline())
                if sum(line.startswith("pose ") for line in lines) > 8:
                    break
            data = read_for(fd, 0.2)
        finally:
            os.close(fd)
    finally:
        proc.send_signal(2)  # Ctrl-C
        out, _ = proc.communicate(timeout=10)
    text = "".join(lines)
    poses = re.findall(r"^pose (\d)/4 (\S+):", text, flags=re.M)
    assert [name for _, name in poses][:5] == ["open", "fist", "thumb-oppose",
                                               "thumb-spread", "open"]
    assert "riIndexMCPy" in text and "closed" in text  # the emulated ranges are printed
    assert "sent " in out and proc.returncode == 0
    assert len(FrameDecoder().feed(data)) >= 20


def test_sim_glove_argument_mistakes_are_one_line(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    from handrig.cli import main

    assert main(["sim-glove"]) == 2
    assert "--calibration" in capsys.readouterr().err
    assert main(["sim-glove", "x.csv", "--calibration"]) == 2
    assert "not both" in capsys.readouterr().err
    assert main(["sim-glove", "x.csv", "--cue"]) == 2
    assert "--cue is for --calibration" in capsys.readouterr().err


def test_each_frame_sent_is_stamped_on_the_monotonic_clock() -> None:
    rec = sweep_recording(0.2, 100.0, 5)
    sent: list[tuple[float, int, int]] = []
    with GloveEmulator(rec, "frames", on_send=lambda t, s, i: sent.append((t, s, i))) as emu:
        fd = open_port(emu.port_path)
        try:
            before = time.clock_gettime(time.CLOCK_MONOTONIC)
            assert emu.done.wait(2.0)
            after = time.clock_gettime(time.CLOCK_MONOTONIC)
            read_for(fd, 0.1)
        finally:
            os.close(fd)
    assert [s for _, s, _ in sent] == list(range(len(rec)))
    assert [i for _, _, i in sent] == list(range(len(rec)))
    times = [t for t, _, _ in sent]
    assert times == sorted(times) and before - 0.5 < times[0] and times[-1] <= after
