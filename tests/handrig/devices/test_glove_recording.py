"""Glove recordings: write/read round trip and clear errors on bad files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from handrig.devices.glove_recording import (
    GloveRecording,
    read_glove_recording,
    sweep_recording,
    write_glove_recording,
)
from handrig.errors import DataError


def test_round_trip(tmp_path: Path) -> None:
    rec = sweep_recording(0.5, 100.0, 5)
    quat = rec.quat_xyzw.copy()
    quat[3] = np.nan  # one sample without an IMU reading
    rec = GloveRecording(rec.t_s, rec.raw, np.arange(len(rec)) % 2, rec.channel_names, quat,
                         100.0, {"note": "test"})
    p = tmp_path / "g.csv"
    write_glove_recording(p, rec)
    back = read_glove_recording(p)
    np.testing.assert_allclose(back.t_s, rec.t_s, atol=1e-6)
    np.testing.assert_array_equal(back.raw, rec.raw)
    np.testing.assert_array_equal(back.buttons, rec.buttons)
    assert np.isnan(back.quat_xyzw[3]).all()
    np.testing.assert_allclose(back.quat_xyzw[4], rec.quat_xyzw[4], atol=1e-6)
    assert back.channel_names == rec.channel_names and back.rate_hz == 100.0
    assert back.meta["note"] == "test"


def test_without_imu_columns(tmp_path: Path) -> None:
    p = tmp_path / "g.csv"
    p.write_text("# handrig glove recording 1\nt_s,a,b,buttons\n0,1,2,0\n0.01,3,4,1\n")
    rec = read_glove_recording(p)
    assert rec.quat_xyzw is None and rec.n_channels == 2
    assert rec.nominal_rate_hz == pytest.approx(100.0)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("t_s,a,buttons\n0,1,0\n", "not a glove recording"),
        ("# handrig glove recording 1\na,t_s,buttons\n", "header must start with t_s"),
        ("# handrig glove recording 1\nt_s,a,buttons\n0,1,0\n0.1,1\n", r"g.csv:4: 2 columns"),
        ("# handrig glove recording 1\nt_s,a,buttons\n0,x,0\n",
         r"g.csv:3: column 'a': 'x' is not a number"),
        ("# handrig glove recording 1\nt_s,a,buttons\n0.1,1,0\n0.1,1,0\n",
             r"g.csv:4: t_s 0.1 does not come after 0.1: the times must increase"),
        ("# handrig glove recording 1\nt_s,a,qx,qy,qz,qw,buttons\n0,1,0,,0,1,0\n",
         "all filled or all empty"),
    ],
)
def test_bad_files_name_the_line(tmp_path: Path, text: str, match: str) -> None:
    p = tmp_path / "g.csv"
    p.write_text(text)
    with pytest.raises(DataError, match=match):
        read_glove_recording(p)


def test_missing_file() -> None:
    with pytest.raises(DataError, match="not found"):
        read_glove_recording("/nonexistent/g.csv")
