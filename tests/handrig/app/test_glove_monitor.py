"""``handrig glove monitor`` against an emulated glove (sim-glove's emulator), as text."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from firmware_protocol.glove import FLAG_IMU_ABSENT, FLAG_SENSOR_RAIL
from handrig.app.glove_monitor import GloveMonitor
from handrig.cli import main
from handrig.devices.glove import GloveSample, GloveStats
from handrig.devices.glove_calibration import load_glove_config
from handrig.devices.glove_recording import read_glove_recording
from sim.glove_emulator import GloveEmulator

DEMO = Path(__file__).resolve().parents[3] / "config" / "recordings" / "demo_glove.csv"


def test_the_monitor_prints_channels_degrees_forearm_rate_and_flags(
        capsys: pytest.CaptureFixture[str]):
    rec = read_glove_recording(DEMO)
    with GloveEmulator(rec, "frames", rate_hz=200.0, loop=True) as emu:
        status = main(["glove", "monitor", "--glove", emu.port_path, "--once", "--seconds", "1.2"])
    out = capsys.readouterr().out
    assert status == 0, out
    rate = float(re.search(r"frames, ([0-9.]+) Hz", out).group(1))  # type: ignore[union-attr]
    assert 190.0 < rate < 210.0, out
    for name in ("riThumbCMCx", "riIndexMCPy", "riPinkyMCPy"):
        assert f"({name})" in out and re.search(rf"\s{name}\s+-?[0-9.]+ deg", out), out
    assert "0 CRC errors" in out and "firmware flags: ok" in out
    assert re.search(r"forearm inclination\s+-?[0-9.]+ deg, rotation\s+-?[0-9.]+ deg \(IMU\)", out)
    bars = re.findall(r"\[([#.|]+)\]\s+(\d+)\s+min\s+(\d+)\s+max\s+(\d+)", out)
    assert len(bars) == 5
    for _bar, latest, low, high in bars:
        assert int(low) <= int(latest) <= int(high)


def sample(raw: list[float], status: int, quat: bool, t: float) -> GloveSample:
    return GloveSample(raw=np.array(raw), quat=np.array([0.0, 0.0, 0.0, 1.0]) if quat else None,
                       buttons=0, estop=False, seq=0, sensor_time_us=0, host_time_s=t, count=1,
                       status=status)


def test_the_monitor_keeps_extremes_and_names_pinned_and_imu_lost():
    cfg = load_glove_config()
    mon = GloveMonitor(cfg)
    mon.add(sample([1000, 2000, 1500, 1200, 1100], 0, True, 0.0))
    mon.add(sample([1800, 1900, 1500, 3000, 4093], FLAG_SENSOR_RAIL | FLAG_IMU_ABSENT, False,
                   0.005))
    text = "\n".join(mon.render(GloveStats(frames_ok=2), 0.006))
    assert "min   1000  max   1800" in text
    assert "sensor-pinned" in text and "imu-absent" in text
    assert "channel 4 (riPinkyMCPy) at full scale" in text
    assert "([forearm] of the config)" in text
    assert f"inclination {cfg.forearm.inclination_deg:6.1f} deg" in text
