"""``handrig calibrate glove`` finds an IMU mounted askew on an emulated glove, the test
holding each pose as a person would: made when the command asks for it, held until it
asks for the next (moved here from tests/handrig/pose/test_imu_mount.py, whose poses
ran on a timer of their own beside the command's: on a loaded machine the two drifted
apart and a pose's hold caught the move into the next one)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from scipy.spatial.transform import Rotation

from handrig.devices.glove_calibration import load_glove_config
from handrig.pose.imu_mount import angle_between_deg, askew_mount
from sim.calibration_motion import ScriptedSensors, move_recording, pose_names
from sim.glove_emulator import GloveEmulator
from tests.handrig.cli.test_calibrate_glove import main

SETTLE_S, HOLD_S = 0.25, 0.35
POSE_WAIT_S = 30.0  # for the emulator's thread to send the new pose (a busy machine)


class Puppeteer:
    """Answers the command's prompts: at each "press Enter" the next pose is made on the
    glove (held, looped) and Enter pressed once the glove has sent it; "write?": yes."""

    def __init__(self, emu: GloveEmulator, poses: list[tuple[str, object]]) -> None:
        self.emu = emu
        self.poses = poses
        self.made: list[str] = []

    def __call__(self, prompt: str = "") -> str:
        if "press Enter" not in prompt:
            return "y"
        name, rec = self.poses[len(self.made)]
        self.made.append(name)
        sent = self.emu.frames_sent
        self.emu.play(rec, loop=True)  # type: ignore[arg-type]
        end = time.monotonic() + POSE_WAIT_S
        while self.emu.frames_sent < sent + 3:  # one frame may still be the old pose's
            assert time.monotonic() < end, f"the emulator never sent pose {name}"
            time.sleep(0.002)
        return ""


def test_calibrate_glove_finds_an_imu_mounted_askew(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    true = askew_mount(30.0, 15.0)
    sensors = ScriptedSensors.from_config(load_glove_config())
    names = pose_names(imu=True)
    held = [(name, move_recording(sensors, name, name, transition_s=0.0, hold_s=1.0,
                                  seed=k, imu_mount=true)) for k, name in enumerate(names)]
    out = tmp_path / "glove.toml"
    with GloveEmulator(held[0][1], "frames", rate_hz=200.0, loop=True) as emu:
        puppet = Puppeteer(emu, held)  # type: ignore[arg-type]
        monkeypatch.setattr("builtins.input", puppet)
        status = main(["calibrate", "glove", "--glove", emu.port_path, "--settle",
                       str(SETTLE_S), "--hold", str(HOLD_S), "--out", str(out)])
    captured = capsys.readouterr()
    text = captured.out
    assert status == 0, (text, captured.err)
    assert puppet.made == list(names)  # every pose asked for, in order
    assert "palm to vertical" in text and "IMU mount_xyzw" in text, text.splitlines()
    found = Rotation.from_quat(load_glove_config(out).imu.mount_xyzw)
    assert angle_between_deg(found, true) < 2.0, (found.as_quat(), true.as_quat())
