"""The factory: glove.toml's IMU settings reach the forearm angles; the glove reader and
the summary get what the calibration and the port counters say."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handrig.app.parts import ForearmAngles
from handrig.devices.glove import GloveSample
from handrig.devices.glove_calibration import ImuSettings, load_glove_config
from handrig.pose.orientation import ForearmOrientation

ENU_TO_NED = Rotation.from_matrix([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def _sample(q: np.ndarray) -> GloveSample:
    return GloveSample(np.zeros(5), q, 0, False, 1, 0, 0.0, 1)


@pytest.mark.parametrize("world,order", [("ENU", "xyzw"), ("NED", "wxyz")])
def test_forearm_angles_honour_order_world_and_mount(world, order):
    rng = np.random.default_rng(7)
    mount = Rotation.random(random_state=rng)  # forearm frame in IMU axes
    cfg = load_glove_config()
    cfg = dataclasses.replace(cfg, imu=ImuSettings(
        order=order, world=world, mount_xyzw=tuple(mount.as_quat())))  # type: ignore[arg-type]
    angles = ForearmAngles(cfg)
    for incl, rot in [(0.0, 0.0), (30.0, 90.0), (-45.0, 170.0), (60.0, -100.0)]:
        forearm_to_enu = Rotation.from_quat(
            ForearmOrientation().quaternion_for(incl, rot, heading_deg=25.0))
        imu_to_world = forearm_to_enu * mount.inv()
        if world == "NED":
            imu_to_world = ENU_TO_NED * imu_to_world
        q = imu_to_world.as_quat(scalar_first=order == "wxyz")
        got = angles(_sample(q))
        np.testing.assert_allclose(got, (incl, rot), atol=1e-6)


def test_a_rejected_quaternion_keeps_the_last_good_angles():
    angles = ForearmAngles(load_glove_config())
    good = angles(_sample(ForearmOrientation().quaternion_for(20.0, 45.0)))
    assert angles(_sample(np.array([0.0, 0.0, 0.0, 0.0]))) == pytest.approx(good)
    assert angles(_sample(np.array([np.nan, 0.0, 0.0, 1.0]))) == pytest.approx(good)
    assert angles.orientation.rejected == 2


def test_the_glove_reader_is_told_how_many_raw_channels_the_calibration_reads() -> None:
    import os

    from handrig.app.factory import open_glove
    from handrig.clock import FakeClock

    cfg = load_glove_config()
    master, slave = os.openpty()  # a port that exists (open_glove checks before opening)
    try:
        glove = open_glove(os.ttyname(slave), cfg, FakeClock())
    finally:
        os.close(master)
        os.close(slave)
    assert glove.min_channels == max(ch.raw_index() for ch in cfg.channels) + 1  # type: ignore[attr-defined]


def test_the_summary_carries_the_glove_port_counters() -> None:
    from handrig.app.summary import summary_dict
    from handrig.devices.glove import GloveStats
    from handrig.loop.stats import RunStats

    stats = GloveStats(frames_ok=10, channel_errors=2, disconnects=1, reconnects=1,
                       last_outage_s=1.25)
    glove = summary_dict(RunStats(), None, stats, True)["glove"]
    assert (glove["channel_errors"], glove["disconnects"], glove["reconnects"],
            glove["last_outage_s"]) == (2, 1, 1, 1.25)


def test_what_the_bus_reads_back_follows_the_loops_cycle_not_the_fixed_rate() -> None:
    """In mode "glove" a cycle comes per glove frame: the full read (position, velocity,
    current) must fit the glove's period, whatever ``[loop] rate_hz`` (the fixed mode's
    rate) says; in mode "fixed" it is that rate."""
    from handrig.app.factory import cycle_rate_hz, read_fields_for
    from handrig.config.paths import CONFIG_DIR
    from handrig.config.rig import load_rig_config

    rig = load_rig_config(CONFIG_DIR / "rig.toml")  # 20 servos at 1 Mbps, mode "glove"
    assert rig.loop.mode == "glove"
    slow = dataclasses.replace(rig, loop=dataclasses.replace(rig.loop, rate_hz=50.0))
    # 4.4 ms of wire for the full read: it fits a 100 Hz glove's 10 ms, not a 200 Hz one's 5 ms
    assert read_fields_for(slow, 100.0) == "motion"
    assert read_fields_for(slow, 200.0) == "position"
    assert cycle_rate_hz(slow, 5000.0) == rig.loop.ceiling_hz
    fixed = dataclasses.replace(slow, loop=dataclasses.replace(slow.loop, mode="fixed"))
    assert cycle_rate_hz(fixed, 200.0) == 50.0 and read_fields_for(fixed, 200.0) == "motion"
