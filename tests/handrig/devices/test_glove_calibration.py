"""Glove calibration: raw counts to control degrees, the glove config, the IMU frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import tomli_w

from handrig.config.loading import CONFIG_DIR
from handrig.devices.glove_calibration import (
    ChannelCalibration,
    FilterSettings,
    GloveCalibration,
    GloveConfig,
    GloveControls,
    glove_config_to_toml,
    load_glove_config,
    recording_from_degrees,
)
from handrig.errors import ConfigError, DataError

DEFAULT_CONTROLS = ("riThumbCMCx", "riThumbCMCy", "riThumbCMCz", "riIndexMCPy", "riPinkyMCPy")


def test_default_config_drives_the_default_maps_controls() -> None:
    cfg = load_glove_config()
    assert cfg.glove.format == "frames"
    assert cfg.curves == DEFAULT_CONTROLS
    cal = GloveCalibration.from_config(cfg)
    for i, ch in enumerate(cfg.channels):
        raw = np.zeros(5)
        raw[ch.index] = ch.raw_open
        assert cal.calibrate(raw)[i] == pytest.approx(ch.open_deg)
        raw[ch.index] = ch.raw_closed
        assert cal.calibrate(raw)[i] == pytest.approx(ch.closed_deg)
    opengloves = load_glove_config(CONFIG_DIR / "glove_opengloves.toml")
    assert opengloves.curves == DEFAULT_CONTROLS


def test_linear_clamped_and_reversed() -> None:
    cal = GloveCalibration([
        ChannelCalibration("riIndexMCPy", 1000, 3000, 0.0, 80.0, index=1),
        ChannelCalibration("riThumbCMCy", 3000, 1000, 20.0, 0.0, index=0),  # reversed sensor
    ])
    out = np.empty(2)
    raw = np.array([2500.0, 2000.0])
    assert cal.calibrate(raw, out) is out
    np.testing.assert_allclose(out, [40.0, 15.0])
    np.testing.assert_allclose(cal.calibrate(np.array([0.0, 9000.0])), [80.0, 0.0])
    np.testing.assert_allclose(cal.calibrate(np.array([9000.0, 0.0])), [0.0, 20.0])
    np.testing.assert_allclose(cal.to_raw(np.array([40.0, 15.0])), [2000.0, 2500.0])


def test_too_few_raw_channels_is_a_clear_error() -> None:
    cal = GloveCalibration.from_config(load_glove_config())
    with pytest.raises(DataError, match=r"sent 3 channels.*channel 4"):
        cal.calibrate(np.zeros(3))


def test_controls_follow_the_maps_order_and_filter() -> None:
    cfg = load_glove_config()
    order = tuple(reversed(DEFAULT_CONTROLS))
    ctl = GloveControls.from_config(cfg, order)
    cal = GloveCalibration.from_config(cfg)
    raw = np.array([2000.0, 2000.0, 2000.0, 2000.0, 2000.0])
    out = np.empty(5)
    assert ctl(raw, 0.0, out) is out
    np.testing.assert_allclose(out, cal.calibrate(raw)[::-1])
    step = raw + 500
    ctl(step, 0.01, out)
    jump = cal.calibrate(step)[::-1]
    assert np.all(np.abs(out - cal.calibrate(raw)[::-1]) < np.abs(jump - cal.calibrate(raw)[::-1]))
    unfiltered = GloveControls(cal, order, FilterSettings(enabled=False))
    np.testing.assert_allclose(unfiltered(step, 0.01, out), jump)


def test_a_map_control_without_a_channel_is_refused() -> None:
    cal = GloveCalibration.from_config(load_glove_config())
    with pytest.raises(ConfigError, match="riMiddleMCPy have no glove channel"):
        GloveControls(cal, (*DEFAULT_CONTROLS, "riMiddleMCPy"))


def test_toml_round_trip(tmp_path: Path) -> None:
    cfg = load_glove_config(CONFIG_DIR / "glove_opengloves.toml")
    p = tmp_path / "g.toml"
    p.write_bytes(tomli_w.dumps(glove_config_to_toml(cfg)).encode())
    assert load_glove_config(p) == cfg


CHANNEL = ('[[channels]]\nindex = 0\ncurve = "riIndexMCPy"\nraw_open = 1000\nraw_closed = 3000\n'
           'open_deg = 0\nclosed_deg = 80\n')


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (CHANNEL.replace("riIndexMCPy", "riIndexMCP"), r"channels\[0\].curve.*did you mean"),
        (CHANNEL.replace("index = 0", 'index = 0\nletter = "A"'), "exactly one of index"),
        (CHANNEL.replace("raw_closed = 3000", "raw_closed = 1000"), "did not move"),
        (CHANNEL.replace("closed_deg = 80", "closed_deg = 150"), "joint limits"),
        (CHANNEL + CHANNEL, r"channels\[1\].curve.*already driven"),
        (CHANNEL.replace("index = 0", 'letter = "A"'), "letter is for OpenGloves"),
        ('[glove]\nformat = "opengloves"\n' + CHANNEL.replace("index = 0", 'letter = "Q"'),
         "unknown OpenGloves key"),
        ("[glove]\nanalog_max = 2047\n" + CHANNEL, "analog_max"),
        ("[imu]\nmount_xyzw = [0, 0, 0, 2]\n" + CHANNEL, "unit quaternion"),
        ("[forearm]\ninclination_deg = 100\n" + CHANNEL, "inclination"),
        ("[filter]\nbeta = -1\n" + CHANNEL, "filter.beta"),
        ("[glove]\n", "no \\[\\[channels\\]\\]"),
    ],
)
def test_bad_configs_name_file_and_key(tmp_path: Path, text: str, match: str) -> None:
    p = tmp_path / "glove.toml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=match) as e:
        load_glove_config(p)
    assert str(p) in str(e.value)


def test_glove_config_defaults_need_channels() -> None:
    with pytest.raises(ConfigError):
        GloveConfig().check()


def test_recording_from_degrees_reads_back_as_the_same_degrees() -> None:
    cfg = load_glove_config()
    cal = GloveCalibration.from_config(cfg)
    t = np.arange(50) / 100.0
    lo = np.array([min(c.open_deg, c.closed_deg) for c in cfg.channels])
    hi = np.array([max(c.open_deg, c.closed_deg) for c in cfg.channels])
    deg = lo + (hi - lo) * (0.5 + 0.4 * np.sin(t[:, None] * 7 + np.arange(5)))
    rec = recording_from_degrees(cal, t, deg)
    assert rec.channel_names == DEFAULT_CONTROLS and rec.quat_xyzw is None
    back = np.array([cal.calibrate(r) for r in rec.raw])
    gains = np.abs([(c.closed_deg - c.open_deg) / (c.raw_closed - c.raw_open)
                    for c in cfg.channels])
    np.testing.assert_allclose(back, deg, atol=float(gains.max()) * 0.5 + 1e-9)
    with pytest.raises(DataError, match="shape"):
        recording_from_degrees(cal, t, deg[:, :3])


def test_a_nan_reading_holds_the_channel_and_never_poisons_the_filter() -> None:
    from handrig.devices.glove_calibration import GloveControls

    cfg = load_glove_config()
    controls = GloveControls.from_config(cfg, cfg.curves)
    out = np.zeros(len(cfg.curves))
    good = np.array([2000.0, 2100.0, 2000.0, 2100.0, 2100.0])
    first = controls(good, 0.0, out).copy()
    bad = good.copy()
    bad[0] = np.nan
    held = controls(bad, 0.005, out).copy()
    assert np.isfinite(held).all() and held[0] == pytest.approx(first[0])
    bad[0] = np.inf  # an inf is held too, not clipped to the range's end
    held = controls(bad, 0.010, out).copy()
    assert held[0] == pytest.approx(first[0])
    after = controls(good, 0.015, out)
    assert np.isfinite(after).all()
    assert controls.calibration.nonfinite == 2
