import re

import numpy as np
import pytest

from handrig import hand
from handrig.errors import HandrigError


def test_fifty_unique_curves_in_the_papers_spelling():
    assert len(hand.CURVE_NAMES) == 50
    assert len(set(hand.CURVE_NAMES)) == 50
    pattern = re.compile(
        r"^(ri|le)(Thumb(CMC[xyz]|MCPz|IPz)|(Index|Middle|Ring|Pinky)(MCP[xyz]|PIPy|DIPy))$"
    )
    for name in hand.CURVE_NAMES:
        assert pattern.match(name), name
    # Names quoted in the paper's tables
    for name in ("riRingMCPy", "lePinkyMCPx", "riThumbIPz", "leThumbCMCz", "riMiddleDIPy"):
        assert name in hand.CURVE_NAMES


def test_twenty_five_per_hand_in_canonical_order():
    for h in hand.HANDS:
        names = [c.name for c in hand.select_curves(hand=h)]
        assert len(names) == 25
        assert all(n.startswith(h) for n in names)
    assert hand.CURVE_NAMES[:5] == (
        "riThumbCMCx", "riThumbCMCy", "riThumbCMCz", "riThumbMCPz", "riThumbIPz",
    )
    assert hand.CURVE_NAMES[25] == "leThumbCMCx"
    assert [hand.curve_index(n) for n in hand.CURVE_NAMES] == list(range(50))


def test_lookups_by_digit_joint_axis_and_motion():
    assert len(hand.select_curves(hand="ri", digit="Thumb")) == 5
    assert len(hand.select_curves(joint="PIP")) == 8
    flex = hand.select_curves(hand="ri", motion=hand.Motion.FLEXION)
    assert [c.name for c in flex] == [
        "riThumbCMCz", "riThumbMCPz", "riThumbIPz",
        "riIndexMCPy", "riIndexPIPy", "riIndexDIPy",
        "riMiddleMCPy", "riMiddlePIPy", "riMiddleDIPy",
        "riRingMCPy", "riRingPIPy", "riRingDIPy",
        "riPinkyMCPy", "riPinkyPIPy", "riPinkyDIPy",
    ]
    assert hand.curve("riIndexMCPx").motion is hand.Motion.ABDUCTION
    assert hand.curve("riIndexMCPz").motion is hand.Motion.TWIST
    assert hand.curve("riThumbCMCy").motion is hand.Motion.ABDUCTION
    assert hand.curve("riThumbCMCx").motion is hand.Motion.TWIST


def test_unknown_names_fail_with_a_suggestion():
    with pytest.raises(HandrigError, match="did you mean 'riIndexMCPy'"):
        hand.curve("riIndxMCPy")
    with pytest.raises(HandrigError, match="unknown digit"):
        hand.select_curves(digit="Toe")


def test_twenty_three_relaxed_hand_dofs():
    for h in hand.HANDS:
        names = hand.DOF_NAMES[h]
        assert len(names) == 23 == len(set(names))
        assert f"{h}WristFlexion" in names and f"{h}WristDeviation" in names
        digit_dofs = [d for d in hand.DOFS[h] if d.curve is not None]
        assert len(digit_dofs) == 21
        assert all(d.name == d.curve and d.curve in hand.CURVE_NAMES for d in digit_dofs)
        # finger MCPz (twist) has no DOF in the relaxed-hand model
        for f in hand.FINGERS:
            assert f"{h}{f}MCPz" not in names
        idx = hand.dof_curve_indices(h)
        assert (idx == -1).sum() == 2
        assert [hand.CURVE_NAMES[i] for i in idx if i >= 0] == [d.curve for d in digit_dofs]


def test_limits_for_every_name_have_flexion_positive():
    for name in hand.ALL_JOINT_NAMES:
        low, high = hand.anatomical_limits_deg(name)
        assert low < high, name
    assert hand.anatomical_limits_deg("riIndexPIPy") == (0.0, 110.0)
    assert hand.anatomical_limits_deg("leWristFlexion") == (-70.0, 80.0)
    assert hand.curve_limits_deg().shape == (50, 2)
    lim = hand.dof_limits_deg("ri")
    assert lim.shape == (23, 2)
    # Every flexion range reaches further into flexion than into extension
    for c in hand.select_curves(motion=hand.Motion.FLEXION):
        low, high = hand.anatomical_limits_deg(c.name)
        assert high > -low


def test_mirroring_round_trips():
    for name in hand.ALL_JOINT_NAMES:
        m = hand.mirror_name(name)
        assert m != name and hand.mirror_name(m) == name
        assert hand.anatomical_limits_deg(m) == hand.anatomical_limits_deg(name)
    rng = np.random.default_rng(0)
    pose = rng.normal(size=(7, 50))
    mirrored = hand.mirror_pose(pose)
    np.testing.assert_array_equal(mirrored[:, :25], pose[:, 25:])
    np.testing.assert_array_equal(hand.mirror_pose(mirrored), pose)
    with pytest.raises(ValueError):
        hand.mirror_pose(np.zeros(49))
