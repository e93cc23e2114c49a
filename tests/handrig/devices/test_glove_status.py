"""The glove's status flags (SPEC.md, "Flags"): codec round trip, the host's events,
and the forearm pose the rig takes when the glove reports its IMU absent."""

from __future__ import annotations

import numpy as np

from firmware_protocol.glove import (
    FLAG_IMU_ABSENT,
    FLAG_IMU_VALID,
    FLAG_SENSOR_RAIL,
    FLAG_WATCHDOG_RESET,
    GloveFrame,
    decode_frame,
    encode_frame,
    pack_payload,
)
from handrig.app.parts import ForearmAngles
from handrig.clock import FakeClock
from handrig.devices.glove import GloveSample, SerialGlove
from handrig.devices.glove_calibration import load_glove_config
from handrig.devices.glove_status import change_messages, pinned_channels, status_names


def test_status_bits_ride_next_to_the_imu_bit_and_round_trip():
    f = GloveFrame(7, 1000, (1, 2, 3), None, 0, FLAG_IMU_ABSENT | FLAG_SENSOR_RAIL)
    assert pack_payload(f)[1] == 0x0A
    assert decode_frame(encode_frame(f)[:-1]).status == FLAG_IMU_ABSENT | FLAG_SENSOR_RAIL
    q = GloveFrame(8, 1000, (1,), (0.0, 0.0, 0.0, 1.0), 0, FLAG_WATCHDOG_RESET | FLAG_IMU_VALID)
    assert pack_payload(q)[1] == FLAG_WATCHDOG_RESET | FLAG_IMU_VALID
    assert decode_frame(encode_frame(q)[:-1]).status == FLAG_WATCHDOG_RESET


def test_the_glove_source_says_once_when_the_flags_change():
    glove = SerialGlove("/dev/null", "frames", clock=FakeClock(),
                        channel_names=["a", "b", "riPinkyMCPy"])
    frames = [GloveFrame(k, 5000 * k, (2000, 2000, 2000), None, 0, st)
              for k, st in enumerate([0, 0, 0, 0, FLAG_IMU_ABSENT, FLAG_IMU_ABSENT, 0])]
    frames += [GloveFrame(7, 35000, (2000, 2000, 4093), None, 0, FLAG_SENSOR_RAIL)]
    for f in frames:
        glove.feed(encode_frame(f), 0.0)
    events = glove.drain_events()
    assert [e.split(" (")[0] for e in events] == [
        "glove reports its IMU lost", "glove reports its IMU back",
        "glove reports a sensor pinned: channel 2"]
    assert "channel 2 (riPinkyMCPy) at full scale (4093)" in events[2]
    assert glove.latest() is not None and glove.peek().status == FLAG_SENSOR_RAIL  # type: ignore[union-attr]


def test_names_and_pinned_channels():
    assert status_names(FLAG_IMU_ABSENT | FLAG_WATCHDOG_RESET) == ["imu-absent", "watchdog-reset"]
    assert pinned_channels([3, 2000, 4090, 1020, 65530]) == [
        (0, "0"), (2, "full scale"), (3, "full scale"), (4, "full scale")]
    assert change_messages(FLAG_IMU_ABSENT, FLAG_IMU_ABSENT, [1.0]) == []


def test_an_absent_imu_puts_the_forearm_on_the_configured_pose():
    cfg = load_glove_config()
    angles = ForearmAngles(cfg)
    tilted = np.array([0.0, -np.sin(np.pi / 8), 0.0, np.cos(np.pi / 8)])  # 45 deg up

    def sample(quat: np.ndarray | None, status: int) -> GloveSample:
        return GloveSample(raw=np.zeros(5), quat=quat, buttons=0, estop=False, seq=0,
                           sensor_time_us=0, host_time_s=0.0, count=1, status=status)

    incl, _ = angles(sample(tilted, 0))
    assert abs(incl - 45.0) < 1e-6
    assert angles(sample(None, 0))[0] == incl  # a dropped reading holds the last good one
    fixed = (cfg.forearm.inclination_deg, cfg.forearm.rotation_deg)
    assert angles(sample(None, FLAG_IMU_ABSENT)) == fixed  # a lost IMU: the configured pose
