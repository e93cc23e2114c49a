"""The scripted calibration motion: poses in the calibration's order, each sensor fully
closed in exactly one pose, so the calibration's own arithmetic finds the scripted ranges."""

from __future__ import annotations

import numpy as np
import pytest

from handrig.cli.calibrate_glove import derive
from handrig.config.paths import installed_config
from handrig.devices.glove_calibration import CALIBRATION_STEPS, load_glove_config
from handrig.errors import DataError
from sim.calibration_motion import (
    POSE_NAMES,
    ScriptedSensors,
    move_recording,
    pose_fraction,
    timed_recording,
)


@pytest.mark.parametrize("name", ["glove.toml", "glove_opengloves.toml"])
def test_every_sensor_closes_fully_in_exactly_one_pose(name: str) -> None:
    cfg = load_glove_config(installed_config(name))
    sensors = ScriptedSensors.from_config(cfg, n_raw=5)
    assert tuple(n for n, _ in CALIBRATION_STEPS) == POSE_NAMES
    for k, curve in enumerate(sensors.curves):
        if not curve:
            continue
        fractions = [pose_fraction(p, curve) for p in POSE_NAMES]
        assert fractions[0] == 0.0 and fractions.count(1.0) == 1, (curve, fractions)
        assert max(fractions) == 1.0
        assert sensors.open_raw[k] != sensors.closed_raw[k]


def test_the_calibration_arithmetic_finds_the_scripted_ranges() -> None:
    cfg = load_glove_config(installed_config("glove.toml"))
    sensors = ScriptedSensors.from_config(cfg, travel=0.8)
    pose_s, rate = 2.0, 200.0
    rec = timed_recording(sensors, pose_s=pose_s, transition_s=0.5, rate_hz=rate,
                          noise_counts=8.0, seed=1)
    assert rec.duration_s == pytest.approx(len(POSE_NAMES) * pose_s, abs=0.01)
    medians = {}
    for i, pose in enumerate(POSE_NAMES):  # what calibrate records: after settling, a hold
        t0 = i * pose_s + 0.8
        rows = (rec.t_s >= t0) & (rec.t_s < t0 + 1.0)
        medians[pose] = np.median(rec.raw[rows], axis=0)
    new, _ = derive(cfg, medians, 4095.0)
    for ch in new.channels:
        k = ch.raw_index()
        span = abs(sensors.closed_raw[k] - sensors.open_raw[k])
        assert ch.raw_open == pytest.approx(sensors.open_raw[k], abs=0.03 * span)
        assert ch.raw_closed == pytest.approx(sensors.closed_raw[k], abs=0.03 * span)


def test_a_move_starts_at_one_pose_and_holds_the_next() -> None:
    sensors = ScriptedSensors.from_config(load_glove_config(installed_config("glove.toml")))
    rec = move_recording(sensors, "open", "fist", transition_s=0.5, hold_s=1.0,
                         noise_counts=0.0)
    sway = 0.011 * np.abs(sensors.closed_raw - sensors.open_raw) + 1
    assert np.all(np.abs(rec.raw[0] - sensors.pose_raw("open")) <= sway)
    assert np.all(np.abs(rec.raw[-1] - sensors.pose_raw("fist")) <= sway)
    with pytest.raises(DataError, match="unknown calibration pose"):
        sensors.pose_raw("wave")
    with pytest.raises(DataError, match="not longer than"):
        move_recording(sensors, "open", "fist", transition_s=1.0, hold_s=0.0)
