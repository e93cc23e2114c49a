"""The glove firmware in the loop: the AVR binary `make firmware` builds runs on an
emulated ATmega328P (simavr, sim/avr_glove/), its sensors and BNO055 driven by the demo
glove recording, its UART on a pty read by the host's real glove source.

Skipped, naming `make firmware-deps`, where the AVR toolchain or simavr is missing.
"""

from __future__ import annotations

import os
import select
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from handrig.app.parts import ForearmAngles, build_parts
from handrig.app.session import LiveOptions, run_live
from handrig.cli import main
from handrig.clock import MonotonicClock
from handrig.devices.glove import GloveSample, SerialGlove
from handrig.devices.glove_calibration import GloveCalibration, load_glove_config
from handrig.devices.glove_recording import GloveRecording, read_glove_recording
from handrig.devices.glove_status import status_names
from handrig.pose.orientation import ForearmOrientation
from sim.avr_glove import AvrGlove, build, toolchain_missing

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "config" / "recordings" / "demo_glove.csv"
INDEX, LITTLE = 3, 4  # raw channels of riIndexMCPy and riPinkyMCPy (config/glove.toml)


@pytest.fixture(scope="module")
def chip_built() -> None:
    missing = toolchain_missing()
    if missing:
        pytest.skip(missing)
    build()


def collect(glove: SerialGlove, seconds: float, enough: int | None = None) -> list[GloveSample]:
    """Every sample the host's glove source decodes in ``seconds`` (none skipped), or
    until ``enough`` came (a loaded machine runs the emulated chip slower than real time)."""
    out: list[GloveSample] = []
    end = time.monotonic() + seconds
    glove.start()
    while time.monotonic() < end and (enough is None or len(out) < enough):
        fd = glove.fileno()
        if fd is not None:
            select.select([fd], [], [], 0.02)
        glove.pump()
        while (b := glove.take_behind()) is not None:
            out.append(b)
        s = glove.take()
        if s is not None:
            out.append(s)
    return out


def recording_at(rec: GloveRecording, t_us: np.ndarray) -> np.ndarray:
    """Index of the recorded row due at each chip time (the harness starts it at reset)."""
    t = (t_us / 1e6) % (rec.t_s[-1] - rec.t_s[0] + (rec.t_s[1] - rec.t_s[0]))
    return np.searchsorted(rec.t_s - rec.t_s[0], t, side="right") - 1


def test_the_emulated_glove_streams_the_recording_into_the_host(chip_built: None):
    rec = read_glove_recording(DEMO)
    with AvrGlove(DEMO) as chip:
        glove = SerialGlove(chip.port, "frames", clock=MonotonicClock(), reader="poll")
        try:
            time.sleep(0.3)  # the IMU's start-up; then the steady state
            samples = collect(glove, 5.0)
            stats = glove.stats()
        finally:
            glove.close()
    samples = samples[1:]  # the first may have waited in the pty
    t_host = np.array([s.host_time_s for s in samples])
    t_us = np.array([s.sensor_time_us for s in samples], dtype=np.float64)
    # frames the chip sent over the span, by their sequence numbers: a test process
    # short of CPU may take fewer than were sent (the source keeps a bounded backlog)
    sent = int(np.unwrap(np.array([s.seq for s in samples], dtype=np.float64),
                         period=65536)[-1] - samples[0].seq)
    rate_chip = sent / ((t_us[-1] - t_us[0]) / 1e6)  # the firmware's own clock
    # the harness holds chip time to the wall clock, never ahead; on a machine with no
    # core to spare for it, the chip runs slower than real time (CI with a core kept busy)
    rate_wall = sent / (t_host[-1] - t_host[0])
    assert abs(rate_chip - 200.0) < 2.0, rate_chip
    assert 100.0 < rate_wall < 202.0, rate_wall
    assert len(samples) > sent / 2, (len(samples), sent)
    assert stats.crc_errors == 0 and stats.decode_errors == 0 and stats.frames_lost == 0, stats
    assert np.all(np.diff(t_us) > 0)
    raw = np.array([s.raw for s in samples])
    rows = recording_at(rec, t_us)
    for ch in (INDEX, LITTLE):
        r = np.corrcoef(raw[:, ch], rec.raw[rows, ch])[0, 1]
        assert r >= 0.99, (ch, r)
    cal = GloveCalibration.from_config(load_glove_config())
    deg = np.array([cal.calibrate(s.raw) for s in samples])
    deg_rec = np.array([cal.calibrate(rec.raw[i]) for i in rows])
    for ch in (INDEX, LITTLE):
        assert np.corrcoef(deg[:, ch], deg_rec[:, ch])[0, 1] >= 0.99
    assert rec.quat_xyzw is not None
    fo = ForearmOrientation()
    got = np.array([fo.angles(s.quat) for s in samples if s.quat is not None])
    want = np.array([fo.angles(rec.quat_xyzw[i]) for s, i in zip(samples, rows, strict=True)
                     if s.quat is not None])
    assert len(got) == len(samples)  # the IMU answered all along
    err = np.abs(got - want)
    err[:, 1] = np.minimum(err[:, 1], 360.0 - err[:, 1])
    assert err.max() < 1.0, err.max(axis=0)
    assert all(s.status == 0 for s in samples), {s.status for s in samples}


def test_no_imu_at_start_streams_on_with_the_configured_forearm(chip_built: None):
    with AvrGlove(DEMO, imu=False) as chip:
        glove = SerialGlove(chip.port, "frames", clock=MonotonicClock(), reader="poll")
        try:
            samples = collect(glove, 6.0, enough=160)  # 0.8 s at 200 Hz on a quiet machine
            events = glove.drain_events()
        finally:
            glove.close()
    assert len(samples) > 150
    assert all(s.quat is None and "imu-absent" in status_names(s.status) for s in samples)
    assert any("IMU lost" in e for e in events), events
    parts = build_parts()
    angles = ForearmAngles(parts.glove_config)
    fixed = (parts.glove_config.forearm.inclination_deg, parts.glove_config.forearm.rotation_deg)
    assert all(angles(s) == fixed for s in samples)


def test_imu_pulled_mid_run_the_rig_reports_it_and_keeps_going(chip_built: None):
    lines: list[str] = []
    with AvrGlove(DEMO) as chip:
        def log(line: str) -> None:
            lines.append(line)
            if "commissioned" in line:  # the loop is about to run: pull the IMU 1 s in
                threading.Timer(1.0, chip.pull_imu).start()

        result = run_live(build_parts(), LiveOptions(
            glove=chip.port, bus="sim", duration_s=2.5, log=log))
    s = result.summary
    assert result.error is None, result.error
    assert s["torque_off"] is True
    assert s["glove"]["crc_errors"] == 0 and s["glove"]["frames_ok"] > 400, s["glove"]
    start = next(i for i, line in enumerate(lines) if "commissioned" in line)
    assert any("IMU lost" in line for line in lines[start:]), lines
    assert not any("IMU lost" in line for line in lines[:start]), lines


def test_a_sensor_pinned_at_full_scale_is_named_in_the_monitor(
        chip_built: None, capsys: pytest.CaptureFixture[str]):
    with AvrGlove(DEMO, pinned={LITTLE: 4095}) as chip:
        status = main(["glove", "monitor", "--glove", chip.port, "--once", "--seconds", "1.2"])
    out = capsys.readouterr().out
    assert status == 0, out
    assert "firmware flags: sensor-pinned" in out, out
    assert "pinned: channel 4 (riPinkyMCPy) at full scale" in out, out
    assert "glove reports a sensor pinned: channel 4 (riPinkyMCPy) at full scale" in out, out
    assert "(IMU)" in out and "0 CRC errors" in out


def test_the_pty_is_plain_bytes(chip_built: None):
    """What the chip sends is SPEC.md frames from the first byte: a raw read decodes."""
    from firmware_protocol.glove import FrameDecoder

    with AvrGlove(DEMO, seconds=0.5, speed=4.0) as chip:
        fd = os.open(chip.port, os.O_RDONLY | os.O_NOCTTY)
        try:
            data = b""
            end = time.monotonic() + 2.0
            while time.monotonic() < end and len(data) < 2000:
                r, _, _ = select.select([fd], [], [], 0.1)
                if r:
                    try:
                        data += os.read(fd, 4096)
                    except OSError:
                        break
        finally:
            os.close(fd)
    dec = FrameDecoder()
    frames = dec.feed(data)
    assert len(frames) > 20 and dec.stats.errors == 0, dec.stats
    assert [f.seq for f in frames] == list(range(frames[0].seq, frames[0].seq + len(frames)))
