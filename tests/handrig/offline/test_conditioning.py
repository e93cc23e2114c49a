"""Conditioning a capture: its calibration offsets, found, recorded, applied; the paper's
analysis unchanged by them; the conditioned capture and the map's hand inside the joints."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from handrig import hand
from handrig.cli import main
from handrig.errors import ConfigError
from handrig.offline import conditioning, mocap
from handrig.offline.analysis import analyze
from handrig.pose.expand import DEFAULT_MAP, DEFAULT_TWO_GLOVE_MAP
from handrig.pose.maps import LinearMap

MAX_OUTSIDE = 0.01  # issue 30: no curve outside its joint limits in more than 1 % of frames


@pytest.fixture(scope="module")
def recorded() -> mocap.MocapCurves:
    return mocap.load_reference(condition=False)


@pytest.fixture(scope="module")
def conditioned() -> mocap.MocapCurves:
    return mocap.load_reference()


def test_the_reference_as_recorded_leaves_its_joints(recorded: mocap.MocapCurves) -> None:
    out = conditioning.outside_fraction(recorded.curves)
    assert out[hand.curve_index("riIndexPIPy")] > 0.4  # what the check below would catch


def test_conditioned_reference_is_inside_its_joint_limits(
        conditioned: mocap.MocapCurves) -> None:
    out = conditioning.outside_fraction(conditioned.curves)
    worst = int(np.argmax(out))
    assert out[worst] <= MAX_OUTSIDE, (hand.CURVE_NAMES[worst], out[worst])
    assert conditioned.offsets_deg is not None
    assert mocap.load_reference("raw").offsets_deg is None  # raw curves never shifted


def test_the_shipped_maps_keep_the_hand_inside_its_joints(
        conditioned: mocap.MocapCurves) -> None:
    for path in (DEFAULT_MAP, DEFAULT_TWO_GLOVE_MAP):
        lm = LinearMap.load(path)
        out = conditioning.outside_fraction(lm.predict(
            conditioned.curves[:, lm.control_indices]))
        assert out.max() <= MAX_OUTSIDE, (path.name, hand.CURVE_NAMES[int(np.argmax(out))])


def test_conditioning_leaves_the_papers_counts_unchanged(recorded: mocap.MocapCurves,
                                                         conditioned: mocap.MocapCurves
                                                         ) -> None:
    raw = mocap.load_reference("raw").curves
    sign, _ = mocap.profile_affine(mocap.load_profile())
    offsets = conditioned.curves - recorded.curves
    assert np.abs(offsets).max() > 20.0  # the conditioning did move curves
    a, b = analyze(raw), analyze(raw + sign * offsets[0])
    assert [s.dofs_left for s in a.stages] == [s.dofs_left for s in b.stages] == [
        50, 44, 19, 41, 11]
    np.testing.assert_allclose(a.range_deg, b.range_deg, atol=1e-9)
    np.testing.assert_allclose(a.rmsd1, b.rmsd1, atol=1e-9)
    np.testing.assert_allclose(a.rmsd2, b.rmsd2, atol=1e-9)
    assert conditioning.analysis_unchanged(raw, sign * offsets[0])[0]


def test_the_profiles_offsets_are_what_find_offsets_finds(
        recorded: mocap.MocapCurves, conditioned: mocap.MocapCurves) -> None:
    assert conditioned.offsets_deg is not None
    np.testing.assert_allclose(conditioning.find_offsets(recorded.curves),
                               conditioned.offsets_deg, atol=1e-9)
    assert not conditioning.find_offsets(conditioned.curves).any()  # nothing left to find
    prof = mocap.load_profile()
    assert prof.calibration.how and prof.calibration.found_on


def test_find_offsets_shifts_a_curve_back_and_copies_together() -> None:
    rng = np.random.default_rng(3)
    y = np.tile(np.array([np.mean(lim) for lim in hand.curve_limits_deg()]), (2000, 1))
    y += rng.normal(0.0, 2.0, y.shape)
    pip, dip = hand.curve_index("riRingPIPy"), hand.curve_index("riRingDIPy")
    y[:, pip] = rng.uniform(-15.0, 40.0, 2000)  # PIP's range starts at 0: 15 deg too low
    y[:, dip] = y[:, pip]  # the device copies PIP to DIP
    y[:2, hand.curve_index("riIndexMCPy")] = -150.0  # two wild frames set no offset
    off = conditioning.find_offsets(y)
    assert 14.5 <= off[pip] <= 15.0 and off[dip] == off[pip]
    assert np.count_nonzero(off) == 2
    assert conditioning.outside_fraction(y + off)[pip] <= MAX_OUTSIDE


def test_calibration_table_is_checked(tmp_path: Path) -> None:
    base = (Path(mocap.PROFILE_DIR) / "perception_neuron.toml").read_text()
    head = base.split("[calibration]")[0]
    for table, key in (
        ('how = "x"\noffsets_deg = { riIndexPIPq = 1.0 }', "riIndexPIPq"),
        ('how = "x"\noffsets_deg = { riIndexPIPy = 400.0 }', "riIndexPIPy"),
        ("offsets_deg = { riIndexPIPy = 4.0 }", "calibration.how"),
    ):
        p = tmp_path / "p.toml"
        p.write_text(head + "[calibration]\n" + table + "\n")
        with pytest.raises(ConfigError, match=key):
            mocap.load_profile(p)


def test_evaluate_reports_conditioning_and_clamps(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["evaluate", str(mocap.REFERENCE_BVH), "--no-compare", "--json"]) == 0
    obj = json.loads(capsys.readouterr().out)
    cond = obj["conditioning"]
    assert cond["applied"] and cond["offsets_deg"]["riIndexPIPy"] == pytest.approx(20.6)
    assert cond["outside_limits_as_recorded"]["riIndexPIPy"] > 0.4
    assert max(cond["outside_limits"].values()) <= MAX_OUTSIDE
    assert obj["map_errors"]["ri_clamped_fraction"] <= MAX_OUTSIDE
    assert main(["evaluate", str(mocap.REFERENCE_BVH), "--no-compare", "--json",
                 "--no-condition"]) == 0
    assert not json.loads(capsys.readouterr().out)["conditioning"]["applied"]
