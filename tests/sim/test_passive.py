"""The relaxed-hand model: Table 2 mapping, tuning (equation 4, Table 1), solvers."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from handrig.errors import ConfigError
from handrig.hand import DOF_NAMES, dof_limits_deg
from sim import passive
from sim.passive import (
    ORIENTATIONS,
    Calibration,
    PassiveHand,
    StaticSolution,
    load_passive_params,
)
from sim.passive_tuning import (
    check,
    default_config,
    release_test,
    time_to_relaxed,
    tune_stiffness,
)


@pytest.fixture(scope="module")
def cfg() -> passive.PassiveHandConfig:
    return load_passive_params()


@pytest.fixture(scope="module")
def hand(cfg: passive.PassiveHandConfig) -> PassiveHand:
    return PassiveHand(cfg)


def test_shipped_config_is_table2_mapped_and_tuned(cfg: passive.PassiveHandConfig) -> None:
    ref = default_config()
    assert cfg.rest_deg == ref.rest_deg
    assert cfg.calibration == ref.calibration
    assert cfg.release_s == ref.release_s
    assert cfg.is_tuned
    # the sign flips the physics asks for: only the wrist side deviation changes sign
    assert cfg.calibration["riWristDeviation"] == Calibration(-29.0, "thumb_up")
    assert cfg.calibration["riWristFlexion"] == Calibration(22.0, "palm_down")
    assert cfg.calibration["riIndexDIPy"] == Calibration(-34.0, "hang")
    assert cfg.calibration["riThumbCMCy"] == Calibration(-2.0, "thumb_up")
    assert cfg.calibration["riThumbCMCz"] == Calibration(6.0, "palm_down")
    assert all(k > 0 for k in cfg.springs().ks_nm_per_rad.values())


def test_check_reproduces_table2_and_table1(cfg: passive.PassiveHandConfig) -> None:
    result = check(cfg)
    assert set(result["deviations"]) == set(cfg.calibration)
    for name, v in result["deviations"].items():
        assert abs(float(v["model"]) - float(v["paper"])) <= 1.0, name
    for test, v in result["relaxation_s"].items():
        assert abs(float(v["model"]) - float(v["paper"])) <= float(v["std"]), test


def test_a_wrong_sign_is_caught_by_the_physics() -> None:
    ref = default_config()
    cal = dict(ref.calibration)
    cal["riWristDeviation"] = Calibration(+29.0, "thumb_up")  # the paper's raw sign
    with pytest.raises(ConfigError, match="riWristDeviation"):
        tune_stiffness(dataclasses.replace(ref, calibration=cal))


def test_stale_tuned_values_are_refused(cfg: passive.PassiveHandConfig) -> None:
    rest = dict(cfg.rest_deg)
    rest["riIndexPIPy"] = 55.0
    with pytest.raises(ConfigError, match="passive tune"):
        dataclasses.replace(cfg, rest_deg=rest).springs()


def test_static_solve_agrees_with_dynamic_settle_and_is_stable(hand: PassiveHand) -> None:
    for inc, rot in ((0.0, 0.0), (0.0, 180.0), (-40.0, 120.0), (60.0, -70.0)):
        sol = hand.solve_static(inc, rot)
        assert sol.stable and sol.residual_nm < 1e-9
        settled, _ = hand.settle(inc, rot, vel_tol_deg_s=1e-4, max_s=20.0)
        np.testing.assert_allclose(sol.q_deg, settled, atol=0.02)


def test_limit_terms_hold_the_range(hand: PassiveHand) -> None:
    lim = dof_limits_deg("ri")
    for inc, rot in ((0.0, 180.0), (60.0, 180.0), (0.0, -90.0), (-90.0, 0.0), (89.0, 0.0)):
        q = hand.solve_static(inc, rot).q_deg
        over = np.maximum(lim[:, 0] - q, 0) + np.maximum(q - lim[:, 1], 0)
        assert over.max() < 3.0, (inc, rot, DOF_NAMES["ri"][int(over.argmax())])
    torque = hand.limit_torque(np.array([lim[i, 1] + 10.0 for i in range(23)]))
    assert np.all(torque < 0)
    assert np.all(hand.limit_torque(hand.rest_deg) == 0)


def test_time_to_relaxed_is_90_percent_of_the_change() -> None:
    t = np.linspace(0, 3, 3001)
    x = 10.0 * np.exp(-t / 0.2)
    assert time_to_relaxed(t, x, 0.0) == pytest.approx(0.2 * math.log(10), abs=2e-3)
    assert time_to_relaxed(t, 10 - x, 10.0, 0.5) == pytest.approx(0.2 * math.log(2), abs=2e-3)


def test_release_moves_the_way_table1_describes(hand: PassiveHand) -> None:
    r = release_test(hand, "wrist_forward")
    assert r.start_deg == pytest.approx(0.0) and r.final_deg == pytest.approx(22.0, abs=1e-3)
    r = release_test(hand, "wrist_side")
    assert r.final_deg == pytest.approx(-29.0, abs=1e-3)
    r = release_test(hand, "fingers")
    assert r.start_deg > r.final_deg  # the loose fist opens


def test_orientations_are_the_papers() -> None:
    assert ORIENTATIONS == {"hang": (-90.0, 0.0), "palm_down": (0.0, 0.0),
                            "thumb_up": (0.0, 90.0)}


def test_left_hand_sags_like_the_right_at_the_same_anatomical_orientation(
    cfg: passive.PassiveHandConfig, hand: PassiveHand,
) -> None:
    left = PassiveHand(cfg, hand="le")
    for inc, rot in ((0.0, 90.0), (20.0, -60.0), (-50.0, 150.0)):
        np.testing.assert_allclose(left.solve_static(inc, rot).q_deg,
                                   hand.solve_static(inc, rot).q_deg, atol=1e-6)


def test_energy_gradient_is_the_residual(hand: PassiveHand) -> None:
    hand.set_orientation(25.0, -140.0)
    rng = np.random.default_rng(3)
    q = np.zeros(23)
    q[hand.idx] = np.radians(hand.rest_deg + rng.uniform(-30, 30, 23))
    r = hand._residual_qpos(q, jac=False)
    grad = np.empty(23)
    for k in range(23):
        dq = np.zeros(23)
        dq[k] = 1e-6
        hand._residual_qpos(q + dq, jac=False)
        e1 = hand._energy_qpos(q + dq)
        hand._residual_qpos(q - dq, jac=False)
        e0 = hand._energy_qpos(q - dq)
        grad[k] = (e1 - e0) / 2e-6
    np.testing.assert_allclose(-grad, r, atol=1e-8)


def test_gains_scale_only_above_the_horizontal(cfg: passive.PassiveHandConfig) -> None:
    factor = cfg.raised_stiffness_factor
    assert factor > 1.0
    for inc in (-90.0, -30.0, 0.0):
        assert passive.stiffness_scale(inc, factor) == 1.0  # Table 2's orientations
    assert passive.stiffness_scale(30.0, factor) == pytest.approx(1.0 + 0.5 * (factor - 1.0))
    assert passive.stiffness_scale(90.0, factor) == pytest.approx(factor)
    ph = PassiveHand(cfg)
    ks = ph.ks
    ph.set_orientation(90.0, 0.0)
    np.testing.assert_allclose(ph.ks, ks)  # the calibrated gains stay as tuned
    np.testing.assert_allclose(ph.model.jnt_stiffness[ph.model.dof_jntid[ph.idx]], factor * ks)
    ph.set_orientation(-90.0, 0.0)
    np.testing.assert_allclose(ph.model.jnt_stiffness[ph.model.dof_jntid[ph.idx]], ks)


def _palm_up_poses_at_50(ph: PassiveHand) -> tuple[StaticSolution, StaticSolution]:
    """The equilibrium at inclination 50, palm up, followed in 2-degree steps from 40
    (forearm being raised) and from 60 (being lowered)."""
    sols = []
    for path in (range(40, 51, 2), range(60, 49, -2)):
        q = None
        for inc in path:
            sol = ph.solve_static(float(inc), 180.0, q)
            q = sol.q_deg
        sols.append(sol)
    return sols[0], sols[1]


def test_fully_relaxed_fingers_buckle_when_raised_and_the_raised_gain_cures_it(
    cfg: passive.PassiveHandConfig, hand: PassiveHand,
) -> None:
    """Table 2 makes each finger joint about as stiff as its own weight's moment; at gain
    factor 1 (the paper's relaxed hand everywhere) a raised palm-up hand has two stable
    poses, fingers bent back or folded into the palm. The shipped factor leaves one."""
    relaxed = PassiveHand(dataclasses.replace(cfg, raised_stiffness_factor=1.0),
                          springs=cfg.springs())
    below, above = _palm_up_poses_at_50(relaxed)
    assert below.stable and above.stable
    assert np.abs(below.q_deg - above.q_deg).max() > 45.0
    below, above = _palm_up_poses_at_50(hand)
    assert below.stable and above.stable
    np.testing.assert_allclose(below.q_deg, above.q_deg, atol=1e-3)
