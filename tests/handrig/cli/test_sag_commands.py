"""``handrig sag``, ``handrig bake`` and ``handrig passive`` on the command line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from handrig.cli import main
from handrig.hand import DOF_NAMES


def test_sag_json_reproduces_the_calibration(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sag", "--inclination", "0", "--rotation", "90", "--json"]) == 0
    dofs = json.loads(capsys.readouterr().out)["dofs"]
    assert list(dofs) == list(DOF_NAMES["ri"])
    assert dofs["riWristDeviation"] == pytest.approx(-29.0, abs=1.0)
    assert main(["sag", "--inclination", "0", "--rotation", "0", "--hand", "le"]) == 0
    text = capsys.readouterr().out
    assert "leWristFlexion" in text and "+22.00" in text


def test_sag_bad_input_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sag", "--inclination", "120", "--rotation", "0"]) == 2
    assert "must be within -90..90" in capsys.readouterr().err
    assert main(["sag", "--grid", str(tmp_path / "none.npz"), "--inclination", "0",
                 "--rotation", "0"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("handrig: error:") and "handrig bake" in err


def test_bake_writes_grid_plot_and_report(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "grid.npz"
    assert main(["bake", "--step-deg", "30", "--out", str(out), "--plot", "--quiet",
                 "--report", str(tmp_path / "rep")]) == 0
    assert out.exists() and out.with_suffix(".png").exists()
    report = json.loads((tmp_path / "rep" / "bake_report.json").read_text())
    assert report["step_deg"] == 30.0 and report["unstable_samples"] == 0
    assert main(["sag", "--grid", str(out), "--inclination", "-90", "--rotation", "0",
                 "--json"]) == 0
    capsys.readouterr()
    assert main(["bake", "--step-deg", "7", "--out", str(out)]) == 2
    assert "divides 90" in capsys.readouterr().err


def test_passive_check_json_keys(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["passive", "check", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert set(result["relaxation_s"]) == {"wrist_forward", "wrist_side", "fingers"}
    for v in result["relaxation_s"].values():
        assert abs(v["model"] - v["paper"]) <= v["std"]
    assert len(result["deviations"]) == 18
    for name, v in result["deviations"].items():
        assert abs(v["model"] - v["paper"]) <= 1.0, name


def test_passive_tune_rewrites_an_equal_config(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    from handrig.config.loading import CONFIG_DIR, load_toml

    out = tmp_path / "passive.toml"
    assert main(["passive", "tune", "--out", str(out)]) == 0
    assert "damping factors" in capsys.readouterr().out
    new, shipped = load_toml(out), load_toml(CONFIG_DIR / "passive_hand.toml")
    assert new["tuned"]["inputs_sha256"] == shipped["tuned"]["inputs_sha256"]
    assert new["rest_deg"] == shipped["rest_deg"]
    for table in ("ks_nm_per_rad", "kd_per_ks_s"):
        for key, value in shipped["tuned"][table].items():
            assert new["tuned"][table][key] == pytest.approx(value, rel=1e-6), key
