"""``handrig retarget check``: the table, the flags and the demo's limit hits."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from handrig.cli import main
from handrig.config.loading import CONFIG_DIR

LEAP_JOINTS = ["if_mcp", "if_rot", "if_pip", "if_dip", "mf_mcp", "mf_rot", "mf_pip", "mf_dip",
               "rf_mcp", "rf_rot", "rf_pip", "rf_dip", "th_cmc", "th_axl", "th_mcp", "th_ipl"]


@pytest.fixture(scope="module")
def leap_json() -> dict:
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["retarget", "check", "--json"]) == 1  # LEAP has flagged joints
    return json.loads(buf.getvalue())


def test_prints_the_table_the_ranges_and_a_summary(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["retarget", "check", "--no-capture"]) == 1  # joints flagged: exit 1
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0].startswith("retarget table: 16 robot joints")
    table = {ln.split()[0]: ln for ln in lines[2:18]}
    assert list(table) == LEAP_JOINTS
    assert re.search(r"  \+[\d.]+ riPinkyMCPy  #", table["rf_mcp"])
    assert "little finger" in table["rf_mcp"]
    assert re.search(r"  -[\d.]+ riIndexMCPx", table["if_rot"])
    assert "riThumbCMCz" in table["th_mcp"] and "riThumbMCPz" in table["th_mcp"]
    assert "at low" in out and "at high" in out and "covers" in out
    checks = {ln.split()[0]: ln for ln in lines if ln.split() and ln.split()[0] in table
              and "%" in ln}
    assert set(checks) == set(LEAP_JOINTS)
    # the demo's share of each robot range is printed; since issue 38 the table follows
    # the human's fingertips, not the demo's range (tests/sim/test_retarget_fit.py)
    assert 0 < int(checks["if_mcp"].split("%")[2].split()[-1]) <= 100
    assert checks["if_rot"].endswith("ok")
    # the summary ends the joint checks (the figures through the robot's model follow)
    assert any("robot joints get inputs past their range from the demo: " in ln
               for ln in lines)


def test_json_counts_how_often_the_demo_hits_each_limit(leap_json: dict) -> None:
    joints = {j["joint"]: j for j in leap_json["joints"]}
    assert list(joints) == LEAP_JOINTS
    assert leap_json["frames"] > 8000  # the whole demo recording, 200 Hz
    for j in joints.values():
        low, high = j["range_deg"]
        d_lo, d_hi = j["demo_deg"]
        # a limit is hit on some frames exactly when the demo's range passes it
        assert (j["demo_low_frac"] > 0) == (d_lo < low), j["joint"]
        assert (j["demo_high_frac"] > 0) == (d_hi > high), j["joint"]
        assert ("demo" in j["flags"]) == (d_lo < low or d_hi > high)
        assert j["capture_deg"] is not None
    assert 0.0 < joints["if_mcp"]["demo_cover_frac"] <= 1.0
    assert set(joints["rf_mcp"]["sources"]) == {"riPinkyMCPy"}


def test_a_table_file_and_a_human_rig(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    p = tmp_path / "t.toml"
    p.write_text('format = "handrig-retarget"\nversion = 1\n'
                 '[joints.grip]\nsources = { riIndexMCPy = 2.0 }\nrange_deg = [0.0, 10.0]\n')
    assert main(["retarget", "check", "--table", str(p), "--no-capture", "--json"]) == 1
    (grip,) = json.loads(capsys.readouterr().out)["joints"]
    assert grip["flags"] == ["demo", "anatomy"] and grip["demo_high_frac"] > 0
    # a table whose range holds every input flags nothing: exit 0
    p.write_text('format = "handrig-retarget"\nversion = 1\n'
                 '[joints.grip]\nsources = { riIndexMCPy = 0.1 }\nrange_deg = [-30.0, 30.0]\n')
    assert main(["retarget", "check", "--table", str(p), "--no-capture", "--json"]) == 0
    (grip,) = json.loads(capsys.readouterr().out)["joints"]
    assert not set(grip["flags"]) & {"demo", "capture"}
    assert main(["retarget", "check", "--rig", str(CONFIG_DIR / "rig.toml")]) == 2
    assert "not a robot rig" in capsys.readouterr().err
    assert main(["retarget"]) == 2
