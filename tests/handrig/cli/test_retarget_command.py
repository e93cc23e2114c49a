"""``handrig retarget check``: the table, the flags and the demo's limit hits."""

from __future__ import annotations

import json
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
    assert "+1.62 riPinkyMCPy" in table["rf_mcp"] and "little finger" in table["rf_mcp"]
    assert "-1 riIndexMCPx" in table["if_rot"]
    assert "+1.2 riThumbCMCz +1.2 riThumbMCPz" in table["th_mcp"]
    assert "at low" in out and "at high" in out and "covers" in out
    checks = {ln.split()[0]: ln for ln in lines if ln.split() and ln.split()[0] in table
              and "%" in ln}
    assert set(checks) == set(LEAP_JOINTS)
    # the table maps the glove's range onto the robot's: the demo's index MCP covers
    # at least 60 % of LEAP's range (issue 28)
    assert int(checks["if_mcp"].split("%")[2].split()[-1]) >= 60
    assert checks["if_rot"].endswith("ok")
    assert "robot joints get inputs past their range from the demo: " in lines[-1]


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
    assert joints["if_mcp"]["demo_cover_frac"] >= 0.6
    assert joints["rf_mcp"]["sources"] == {"riPinkyMCPy": 1.62}


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
