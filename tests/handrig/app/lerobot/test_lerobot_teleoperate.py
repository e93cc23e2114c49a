"""LeRobot's own `lerobot-teleoperate` console script with handrig's plugins, found by
LeRobot's plugin discovery: the glove (a take held at one pose, `replay:`) through the
LEAP preset's retarget drives the LEAP hand on the emulated bus, which this test hosts
(the emulated servos and the LEAP MuJoCo model, as `port: sim` runs them in the robot's
process), so it watches the Goal Position each servo holds while LeRobot runs and the
Torque Enable each holds after it ends. Skipped without LeRobot (`make lerobot-deps`)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from handrig.app.lerobot.teleop import GloveTeleop
from handrig.app.simulator import servo_bus
from handrig.clock import FakeClock
from handrig.devices.glove.replay import ReplayGlove
from handrig.devices.glove_recording import read_glove_recording
from handrig.devices.servo.positions import ticks_to_deg
from handrig.pose.robot_rig import load_rig
from tests.helpers.lerobot import skip_without_lerobot, unfiltered_glove_file, write_ramp_take

skip_without_lerobot()

RUN_S = 120.0  # --teleop_time_s: a bound; the test ends the run with Ctrl-C (SIGINT) once
HELD_S = 1.0  # the goals have held the glove's pose this long, as seen from outside
FIST_COUNTS = 2600  # the take's index MCP channel: the index flexed, far from relaxed
GRAVITY_DEG = 1.5
"""How far a goal on the bus may be from the glove's target: the LEAP rig's gravity
compensation (``[robot] gravity``) moves each goal by the fingers' weight over the
servo's stiffness, under 1 deg at this pose (1 tick is 0.09 deg)."""


def held_pose(glove: GloveTeleop, take: Path) -> np.ndarray:
    """The action (LEAP joint targets, bus order) of the take's one pose, through the
    teleoperator's own pipeline."""
    clock = FakeClock()
    replay = ReplayGlove(read_glove_recording(take), clock)
    replay.start()
    clock.sleep_until(0.5)
    sample = replay.latest()
    assert sample is not None
    return glove.pose_function()(sample)


def test_lerobot_teleoperate_drives_the_emulated_hand_from_the_glove_and_ends_torque_off(
        tmp_path: Path) -> None:
    take = write_ramp_take(tmp_path / "held.csv", rows=round(RUN_S * 100), row_s=0.01,
                           start=FIST_COUNTS, step=0)  # the glove never falls silent
    glove_file = unfiltered_glove_file(tmp_path / "glove.toml")
    glove = GloveTeleop(port=f"replay:{take}", robot="leap", glove_config=str(glove_file))
    expected = held_pose(glove, take)
    moved = np.abs(expected - glove.relaxed()) > 5.0
    assert moved.any()  # the held pose is not where the hand rests: following shows

    rig = load_rig("leap")
    sim, _puppet = servo_bus(rig, wire_timing=True, realtime=False)
    home = tmp_path / "home"
    env = dict(os.environ, HOME=str(home), XDG_CACHE_HOME=str(home / ".cache"),
               HF_HOME=str(home / "hf"), HF_LEROBOT_HOME=str(home / "hf/lerobot"),
               HF_HUB_OFFLINE="1")
    script = Path(sys.executable).parent / "lerobot-teleoperate"
    goals_seen: list[np.ndarray] = []
    seen_at: list[float] = []
    with sim:
        proc = subprocess.Popen(
            [str(script), "--robot.type=handrig_leap", f"--robot.port={sim.port_path}",
             "--teleop.type=handrig_glove", f"--teleop.port=replay:{take}",
             "--teleop.robot=leap", f"--teleop.glove_config={glove_file}",
             "--teleop.fps=30", "--fps=30", f"--teleop_time_s={RUN_S:g}"],
            cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        interrupted = False
        held_since: float | None = None
        try:
            while proc.poll() is None:  # the goals each emulated servo holds, as it runs
                goals = np.array([ticks_to_deg(s, sim.servo(s.id).goal) for s in rig.servos])
                now = time.monotonic()
                goals_seen.append(goals)
                seen_at.append(now)
                if np.all(np.abs(goals - expected) <= GRAVITY_DEG):
                    held_since = now if held_since is None else held_since
                else:
                    held_since = None
                if (not interrupted and held_since is not None
                        and now - held_since >= HELD_S):
                    proc.send_signal(signal.SIGINT)  # Ctrl-C, as a user ends it
                    interrupted = True
                time.sleep(0.01)
            out, err = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
        torque = {s.id: sim.servo(s.id).torque_enabled for s in rig.servos}
    assert interrupted, (  # the run's whole 120 s went by without the pose held 1 s
        "the goals never held the glove's pose for 1 s: the closest was "
        f"{np.abs(np.array(goals_seen) - expected).max(axis=1).min():.2f} deg off")
    assert proc.returncode == 0, err[-3000:]
    assert "Teleop loop time" in out  # LeRobot's own loop ran
    assert "Traceback" not in err, err[-3000:]
    assert not any(torque.values()), torque  # every servo of the hand ends torque off

    # the hand followed the glove: at some moment every servo's goal was the held
    # pose's target (less gravity's offset), and the joints it moves were away from it
    # before (by more than 5 deg: at rest)
    goals = np.array(goals_seen)
    at_pose = np.all(np.abs(goals - expected) <= GRAVITY_DEG, axis=1)
    assert at_pose.any(), (
        "the goals never reached the glove's pose: the closest was "
        f"{np.abs(goals - expected).max(axis=1).min():.2f} deg off")
    first = int(np.argmax(at_pose))
    assert np.any(np.abs(goals[:first, moved] - expected[moved]) > 5.0)
    # ... and stayed there while LeRobot's loop ran, until Ctrl-C (the ease to rest and
    # torque off come after)
    held = np.asarray(seen_at)[at_pose]
    assert held[-1] - held[0] >= HELD_S, held[-1] - held[0]
    assert not os.listdir(home / "hf" / "lerobot" / "calibration" / "robots" /
                          "handrig_leap")  # LeRobot kept no calibration of its own
