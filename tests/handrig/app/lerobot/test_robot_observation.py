"""The LeRobot robot's observation is the loop's newest read of the servos, whole, with
the time that read ended: not the telemetry snapshot (published at most 30 times a
second, so up to 33 ms older), not an average. handrig's side of `handrig_leap`
(:class:`HandRobot`, no LeRobot needed) on an in-process emulated LEAP hand whose
servos move kinematically while the test asks."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import numpy as np
import pytest

from handrig.app.lerobot.hand import CURRENT, POS, HandRobot
from handrig.config.rig_files import rig_file_path
from sim.dxl_bus import SimBus

ASK_S = 1.0


@pytest.fixture
def leap() -> Iterator[HandRobot]:
    with SimBus.from_rig(rig_file_path("leap"), realtime=False) as sim:
        robot = HandRobot("leap", sim.port_path)
        robot.connect()
        try:
            yield robot
        finally:
            robot.disconnect()
        assert robot.torque_off_confirmed is True


def test_the_observation_is_the_newest_read_with_the_time_it_ended(leap: HandRobot) -> None:
    robot = leap
    assert math.isnan(robot.observed_at_s)
    loop = robot.hand._open_loop()  # the loop's own newest read, to compare with
    names = robot.joint_names
    # the hand closes and opens its index and middle fingers while LeRobot would ask
    bent = {f"{j}.pos": 60.0 for j in ("if_mcp", "if_pip", "mf_mcp", "mf_pip")}
    robot.send({**{f"{j}.pos": 0.0 for j in names}, **bent})
    matched = newer_than_snapshot = 0
    index_mcp: list[float] = []
    asked = 0
    t_end = time.monotonic() + ASK_S
    while time.monotonic() < t_end:
        if asked == 50:
            robot.send({k: 0.0 for k in bent})
        before = loop.newest_reading()
        obs = robot.observation()
        after = loop.newest_reading()
        snap = loop.snapshot()
        asked += 1
        time.sleep(0.005)  # LeRobot asks once a frame; this asks at about 150 Hz
        assert set(obs) == {j + POS for j in names} | (
            {j + CURRENT for j in names} if robot.reads_current else set())
        if before is None or before is not after:
            continue  # a read ended during the call: either may be the one it gave
        matched += 1
        # whole: every joint's value from that one read, and its time
        assert robot.observed_at_s == before.timestamp_s
        fresh = np.asarray(before.age_s) <= robot.hand.rig.silence.hold_s
        want = np.where(fresh, np.asarray(before.positions_deg), math.nan)
        np.testing.assert_array_equal([obs[j + POS] for j in names], want)
        index_mcp.append(obs["if_mcp.pos"])
        if snap is not None and snap.positions_deg:
            snap_read_s = snap.t_s - max(snap.reading_ages_s)
            assert before.timestamp_s >= snap_read_s  # never older than the snapshot's
            newer_than_snapshot += before.timestamp_s > snap.t_s
    assert matched >= asked // 2, (matched, asked)
    # the joints moved while asked (so a stale value would have shown), and the newest
    # read was often newer than the snapshot: what the observation was before
    assert np.nanmax(index_mcp) - np.nanmin(index_mcp) > 30.0
    assert newer_than_snapshot > 0, (newer_than_snapshot, matched)
