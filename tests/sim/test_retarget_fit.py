"""Retargeting through the robot's kinematics: the hand model's grasps, the palm frame,
the shipped tables' figures (fist, pinch, fingertips) and the fit itself."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from handrig import hand
from handrig.offline.mocap import load_reference
from handrig.pose.retarget import Retarget, load_retarget, table_text
from handrig.pose.robot_rig import RobotRigConfig, load_rig, robot_retarget
from sim.grasp_poses import PINCH_TOUCH_MM, fist_pose, pinch_poses
from sim.hand_kinematics import HumanTips
from sim.retarget_fit import GraspModel, digit_chains, fit_retarget

PRESETS = ("leap", "orca")


def _rig(name: str) -> tuple[Retarget, str]:
    rig = load_rig(name)
    assert isinstance(rig, RobotRigConfig) and rig.robot is not None
    return robot_retarget(rig), rig.robot.model


@pytest.fixture(scope="module")
def capture() -> np.ndarray:
    return load_reference().curves


@pytest.fixture(scope="module", params=PRESETS)
def graded(request: pytest.FixtureRequest, capture: np.ndarray) -> tuple[str, GraspModel, dict]:
    rt, model = _rig(request.param)
    gm = GraspModel(rt, model, capture)
    return request.param, gm, gm.grade(rt).as_json()


def test_the_hand_models_pinches_touch_and_its_fist_is_closed() -> None:
    tips = HumanTips()
    pinches = pinch_poses(tips)
    assert {p.finger for p in pinches} == {"Index", "Middle"}
    t = tips.digits.index("Thumb")
    for p in pinches:
        pos = tips.tips(p.pose_deg)[0]
        gap_mm = 1000 * np.linalg.norm(pos[t] - pos[tips.digits.index(p.finger)])
        assert gap_mm <= PINCH_TOUCH_MM and gap_mm == pytest.approx(p.gap_mm, abs=1e-6)
        # the thumb flexes toward the finger: a pinch, not a straight thumb laid on it
        assert p.pose_deg[hand.curve_index("riThumbIPz")] > 5.0
    fist = fist_pose()
    assert fist[hand.curve_index("riIndexPIPy")] == hand.anatomical_limits_deg("riIndexPIPy")[1]
    assert not fist[25:].any()  # the left hand stays open


def test_the_palm_frame_is_distal_radial_dorsal_on_both_hands() -> None:
    human = HumanTips()
    straight = human.tips(np.zeros(50))[0]
    assert np.all(straight[1:, 0] > 0.05)  # fingers point distal (+x)
    index, pinky = human.digits.index("Index"), human.digits.index("Pinky")
    assert straight[index, 1] > straight[pinky, 1]  # the index is radial (+y)
    for name in PRESETS:
        rt, model = _rig(name)
        gm = GraspModel(rt, model)
        q = np.zeros(len(rt.joint_names))
        flat = gm.robot_tips(q)[0]
        for finger, joints in gm.chains.items():
            if finger == "Thumb":
                continue
            bent = q.copy()
            bent[[rt.index(j) for j in joints if gm._is_flexion(rt, rt.index(j))]] = 30.0
            k = gm.robot.digits.index(finger)
            # flexing a robot finger moves its tip palmar (-z), as a human's
            assert gm.robot_tips(bent)[0][k, 2] < flat[k, 2] - 0.02, (name, finger)


def test_digit_chains_follow_the_tables_sources() -> None:
    rt, _ = _rig("leap")
    chains = digit_chains(rt)
    assert chains["Pinky"] == ["rf_mcp", "rf_rot", "rf_pip", "rf_dip"]  # LEAP's ring
    assert set(chains) == {"Thumb", "Index", "Middle", "Pinky"}


def test_the_shipped_tables_close_fists_and_pinch(graded: tuple[str, GraspModel, dict]) -> None:
    name, gm, g = graded
    assert set(g["fist_closure"]) == {d.lower() for d in gm.chains if d != "Thumb"}
    for finger, closure in g["fist_closure"].items():
        assert closure >= 0.9, (name, finger, closure)
    assert set(g["pinch_gap_mm"]) == {"thumb_index", "thumb_middle"}
    for pair, gap in g["pinch_gap_mm"].items():
        assert gap <= 10.0, (name, pair, gap)
    err = g["tip_error_mm"]
    assert 0.0 < err["median"] < err["p95"]
    # the fingers (not LEAP's thumb, mounted unlike a human's) follow within 25 mm median
    for digit in gm.chains:
        if digit != "Thumb":
            assert err[f"{digit.lower()}_median"] < 25.0, (name, digit, err)


def test_closure_and_pinch_gaps_measure_the_robot_not_the_table(
        graded: tuple[str, GraspModel, dict]) -> None:
    name, gm, _ = graded
    rt, _model = _rig(name)
    # the same table with every gain halved: the fist opens and the pinches part
    half = dataclasses.replace(rt, gain=rt.gain * 0.5, table=None)
    g = gm.grade(half).as_json()
    assert min(g["fist_closure"].values()) < 0.9
    assert max(g["pinch_gap_mm"].values()) > 10.0


def test_a_fit_from_a_spoilt_table_pinches_again_and_writes_a_table_that_loads(
        tmp_path: Path, capture: np.ndarray) -> None:
    rt, model = _rig("orca")
    spoilt = dataclasses.replace(rt, gain=rt.gain * 0.5, table=rt.table)
    before = GraspModel(spoilt, model).grade(spoilt).pinch_gap_mm
    res = fit_retarget(spoilt, model, capture[::5], max_evaluations=3)
    assert res.before.pinch_gap_mm == pytest.approx(before)
    assert max(res.after.pinch_gap_mm.values()) < 0.5 * max(before.values())
    fitted = res.retarget
    assert np.array_equal(fitted.low_deg, rt.low_deg)  # ranges are the model's, kept
    assert np.array_equal(fitted.high_deg, rt.high_deg)
    assert fitted.gain[rt.index("right_wrist")].sum() == 0.0  # no sources: left alone
    # each joint keeps its sources and their signs: no thumb joint starts reading another
    # thumb curve (which moved LEAP's thumb base against its own glove channel)
    assert np.array_equal(np.sign(fitted.gain), np.sign(spoilt.gain))
    p = tmp_path / "orca_fit.toml"
    p.write_text(table_text(fitted, "a header\nof two lines"))
    back = load_retarget(p)
    assert back.joint_names == rt.joint_names
    assert np.array_equal(back.gain, fitted.gain)
    assert np.array_equal(back.offset_deg, fitted.offset_deg)
    assert p.read_text().startswith("# a header\n# of two lines\n")


def test_held_joints_stay_and_a_held_thumb_drops_the_pinch_terms(capture: np.ndarray) -> None:
    rt, model = _rig("orca")
    spoilt = dataclasses.replace(rt, gain=rt.gain * 0.5, table=rt.table)
    thumb = ["right_t-cmc", "right_t-abd", "right_t-mcp", "right_t-pip"]
    res = fit_retarget(spoilt, model, capture[::20], max_evaluations=2, hold=thumb)
    for joint in thumb:
        k = rt.index(joint)
        assert np.array_equal(res.retarget.gain[k], spoilt.gain[k])
        assert res.retarget.offset_deg[k] == spoilt.offset_deg[k]
    assert not np.array_equal(res.retarget.gain, spoilt.gain)  # the fingers were fitted
    with pytest.raises(KeyError, match="right_t-cmc"):
        fit_retarget(spoilt, model, capture[::20], max_evaluations=1, hold=["t-cmc"])
