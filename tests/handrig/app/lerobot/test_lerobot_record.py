"""LeRobot's own record loop with handrig's plugins on the simulated rig (the real
LeRobot package; skipped without it: `make lerobot-deps`).

A glove take with a known time course (index MCP a ramp, 100 rows a second) is the
teleoperator's input; `lerobot-record`'s loop (its `record`, in this process) records
it at 30 fps through the LEAP preset's retarget onto the emulated LEAP hand. LeRobot's
`LeRobotDataset` then loads the dataset: the frames are stamped k/30 s, and frame k's
action is the take's newest row at one fixed offset plus k/30 s, through the pipeline:
on the frame grid, never a row from another moment, never a blend of rows. The episode
then goes back onto the simulated hand as `lerobot-replay` plays it, and the goals the
hand's loop writes on the emulated bus follow the recorded actions.
"""

from __future__ import annotations

import logging
import math
import os
import time
from pathlib import Path

import numpy as np
import pytest

from handrig.app.lerobot.teleop import GloveTeleop
from handrig.clock import FakeClock
from handrig.devices.glove.replay import ReplayGlove
from handrig.devices.glove_recording import read_glove_recording
from tests.helpers.lerobot import skip_without_lerobot, unfiltered_glove_file, write_ramp_take

skip_without_lerobot()

FPS = 30
ROW_S = 0.01  # the take's rows: 100 a second
ROWS = 800
EPISODE_S = 3


class Said(logging.Handler):
    """The warnings a logger gave, kept."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


@pytest.fixture
def lerobot_home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    for var, sub in (("HF_HOME", "hf"), ("HF_LEROBOT_HOME", "hf/lerobot")):
        monkeypatch.setenv(var, str(tmp_path / sub))
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    return tmp_path


def test_record_stamps_frames_on_the_grid_and_replay_reaches_the_bus(
        lerobot_home: Path) -> None:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from lerobot.robots.utils import make_robot_from_config
    from lerobot.scripts.lerobot_record import DatasetRecordConfig, RecordConfig, record
    from lerobot.utils.constants import ACTION
    from lerobot_robot_handrig import HandrigHand, HandrigLeapConfig
    from lerobot_teleoperator_handrig import HandrigGloveConfig

    take = lerobot_home / "ramp.csv"
    write_ramp_take(take, ROWS, ROW_S, start=1100, step=2)
    glove_file = unfiltered_glove_file(lerobot_home / "glove.toml")
    root = lerobot_home / "dataset"
    teleop = HandrigGloveConfig(port=f"replay:{take}", robot="leap", fps=FPS,
                                glove_config=str(glove_file), max_lag_s=10.0)
    cfg = RecordConfig(
        robot=HandrigLeapConfig(port="sim"), teleop=teleop, play_sounds=False,
        dataset=DatasetRecordConfig(
            repo_id="local/handrig_ramp", single_task="ramp", root=root, fps=FPS,
            episode_time_s=EPISODE_S, reset_time_s=0, num_episodes=1, video=False,
            push_to_hub=False))
    said = Said()  # what the teleoperator warns of (LeRobot clears the root's handlers)
    teleop_log = logging.getLogger("handrig.app.lerobot.teleop")
    teleop_log.addHandler(said)
    try:
        record(cfg)
    finally:
        teleop_log.removeHandler(said)

    ds = LeRobotDataset("local/handrig_ramp", root=root)
    names = ds.features[ACTION]["names"]
    n = len(ds)
    assert ds.fps == FPS and n >= FPS  # the loop stops by its own clock: about 90
    frames = [ds[i] for i in range(n)]
    stamps = np.array([f["timestamp"].item() for f in frames])
    np.testing.assert_allclose(stamps, np.arange(n) / FPS, atol=1e-6)
    actions = np.stack([f[ACTION].numpy() for f in frames]).astype(np.float64)

    # every row of the take through the teleoperator's own pipeline
    glove = GloveTeleop(port=f"replay:{take}", robot="leap", glove_config=str(glove_file))
    assert tuple(names) == glove.names
    clock = FakeClock()
    replay = ReplayGlove(read_glove_recording(take), clock)
    replay.start()  # the take's time 0 at the clock's 0
    pose_of = glove.pose_function()
    rows = []
    for i in range(ROWS):
        clock.sleep_until(i * ROW_S + 1e-7)  # row i due, row i + 1 not
        sample = replay.latest()
        assert sample is not None and sample.count == i + 1
        rows.append(pose_of(sample))
    expected = np.array(rows)
    # the joint the ramp moves at every row tells the rows apart (LEAP's index MCP rests
    # at its limit while the human index is open, so it is not always the one)
    steps = np.diff(expected, axis=0)
    col = int(np.argmax(np.min(np.abs(steps), axis=0)))
    assert np.min(np.abs(steps[:, col])) > 0.01, names[col]  # far above float32's 1e-5
    assert np.all(steps[:, col] > 0) or np.all(steps[:, col] < 0), names[col]

    index = np.array([int(np.argmin(np.abs(expected[:, col] - a))) for a in actions[:, col]])
    # each frame's action is one row of the take, whole (float32 in the dataset)
    np.testing.assert_allclose(actions, expected[index], atol=1e-3)
    # ... the newest row at offset + k / fps for one offset: row i is newest over
    # [i, i + 1) * ROW_S, so the offset lies in every frame's interval
    k = np.arange(n)
    low = np.max(index * ROW_S - k / FPS)
    high = np.min((index + 1) * ROW_S - k / FPS)
    behind = [m for m in said.messages if "did not keep up" in m]
    assert low < high or behind, (
        "the actions are not the take's rows on a 1/30 s grid, and the teleoperator "
        f"did not say its glove thread fell behind: rows {index.tolist()} "
        f"(row steps {np.diff(index).tolist()})")
    assert np.all(np.diff(index) >= 0), index.tolist()  # never a row from before

    # lerobot-replay's loop: each recorded action sent at the dataset's fps
    robot = make_robot_from_config(HandrigLeapConfig(port="sim"))
    assert isinstance(robot, HandrigHand)
    robot.connect()
    try:
        for a in actions:
            start = time.perf_counter()
            robot.get_observation()
            robot.send_action(dict(zip(names, a.tolist(), strict=True)))
            time.sleep(max(0.0, 1.0 / FPS - (time.perf_counter() - start)))
        last = dict(zip(names, actions[-1].tolist(), strict=True))
        deadline = time.perf_counter() + 5.0
        while True:
            goals = robot.hand.goals()
            if all(abs(goals[j] - last[j]) < 1e-3 for j in names) or \
                    time.perf_counter() > deadline:
                break
            time.sleep(0.02)
        # the goals the loop wrote on the bus are the last action (the LEAP's limits
        # hold every recorded value: they came through its retarget)
        assert {j: round(goals[j], 3) for j in names} == {j: round(last[j], 3) for j in names}
        seen = robot.get_observation()
        assert all(math.isfinite(seen[j]) for j in names)  # read back from the emulated bus
    finally:
        robot.disconnect()
    assert robot.hand.torque_off_confirmed is True
    assert not os.listdir(lerobot_home / "hf" / "lerobot" / "calibration" / "robots" /
                          "handrig_leap")  # LeRobot kept no calibration of its own
