"""The glove as a LeRobot teleoperator, handrig's side (no LeRobot needed): a glove take
played in its own thread through the pipeline, the 50 curves named, each answer one
sample's pose, and the relaxed pose once the glove has been silent for the rig's
glove timeout."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from handrig import hand
from handrig.app.lerobot.teleop import GloveTeleop
from handrig.clock import FakeClock
from handrig.devices.glove.replay import ReplayGlove
from handrig.devices.glove_recording import read_glove_recording
from tests.helpers.lerobot import unfiltered_glove_file, write_ramp_take

ROWS = 100  # half a second at 200 Hz


def test_curves_from_the_take_then_the_relaxed_pose_when_it_ends(tmp_path: Path) -> None:
    take = write_ramp_take(tmp_path / "take.csv", ROWS, 0.005, start=1500, step=10)
    glove_file = str(unfiltered_glove_file(tmp_path / "glove.toml"))

    # every row through a second teleoperator's pipeline
    reference = GloveTeleop(port=f"replay:{take}", glove_config=glove_file)
    clock = FakeClock()
    replay = ReplayGlove(read_glove_recording(take), clock)
    replay.start()
    pose_of = reference.pose_function()
    rows = []
    for i in range(ROWS):
        clock.sleep_until(i * 0.005 + 1e-7)
        sample = replay.latest()
        assert sample is not None
        rows.append(pose_of(sample))
    expected = np.array(rows)

    glove = GloveTeleop(port=f"replay:{take}", glove_config=glove_file)
    assert glove.names == tuple(f"{c}.pos" for c in hand.CURVE_NAMES)
    assert glove.is_calibrated  # a take (and a glove file given) needs none of yours
    glove.connect()
    try:
        seen = []
        while len(seen) < 20:
            action = glove.action()
            values = np.array([action[n] for n in glove.names])
            seen.append(int(np.argmin(np.abs(expected - values).max(axis=1))))
            # one sample's pose, whole: not a blend of two
            np.testing.assert_allclose(values, expected[seen[-1]], atol=1e-9)
            time.sleep(0.01)
        assert seen == sorted(seen) and seen[-1] > seen[0]  # newer rows as time goes on
        time.sleep(ROWS * 0.005 + glove.glove_timeout_s + 0.05)  # the take over, then the timeout
        relaxed = glove.action()
        np.testing.assert_allclose([relaxed[n] for n in glove.names], glove.relaxed())
        assert np.abs(glove.relaxed() - expected[-1]).max() > 1.0
    finally:
        glove.disconnect()
    assert not glove.is_connected
