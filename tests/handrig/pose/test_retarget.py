"""The retarget table: format, loader, the compiled linear step and the range check."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from handrig import hand
from handrig.config.loading import CONFIG_DIR
from handrig.errors import ConfigError, DataError
from handrig.pose.mjcf import MjcfJoint
from handrig.pose.retarget import Retarget, check_joints, load_retarget, retarget

LEAP_TABLE = CONFIG_DIR / "rigs" / "leap_retarget.toml"
HEADER = 'format = "handrig-retarget"\nversion = 1\n'


def _table(tmp_path: Path, body: str) -> Path:
    p = tmp_path / "t.toml"
    p.write_text(HEADER + body)
    return p


def test_table_compiles_to_one_matrix_and_the_step_matches_the_formula(tmp_path: Path) -> None:
    p = _table(tmp_path, """
[joints.a]
sources = { riIndexMCPy = 1.0, riIndexPIPy = 0.5 }
offset_deg = 10.0
range_deg = [-20.0, 60.0]

[joints.b]
sources = { riPinkyMCPx = -1.0 }
range_deg = [-30.0, 30.0]

[joints.c]
range_deg = [0.0, 5.0]
offset_deg = 2.0
""")
    rt = load_retarget(p)
    assert rt.joint_names == ("a", "b", "c")
    assert rt.gain.shape == (3, 50)
    assert rt.gain[0, hand.curve_index("riIndexMCPy")] == 1.0
    assert rt.gain[0, hand.curve_index("riIndexPIPy")] == 0.5
    assert rt.gain[1, hand.curve_index("riPinkyMCPx")] == -1.0
    assert np.count_nonzero(rt.gain) == 3
    human = np.zeros(50)
    human[hand.curve_index("riIndexMCPy")] = 20.0
    human[hand.curve_index("riIndexPIPy")] = 40.0
    human[hand.curve_index("riPinkyMCPx")] = 50.0  # past b's range
    got = rt.apply(human)
    assert got.tolist() == [50.0, -30.0, 2.0]  # 10 + 20 + 20; clipped; held at the offset
    # many frames, and the same numbers before the clip
    many = np.stack([human, np.zeros(50)])
    assert rt.apply_many(many)[0].tolist() == got.tolist()
    assert rt.unclipped_many(many)[0].tolist() == [50.0, -50.0, 2.0]


def test_the_pure_step_writes_into_out_and_allocates_nothing() -> None:
    rt = load_retarget(LEAP_TABLE)
    out = np.empty(len(rt.joint_names))
    human = np.linspace(-10.0, 60.0, 50)
    res = retarget(human, rt.gain, rt.offset_deg, rt.low_deg, rt.high_deg, out)
    assert res is out
    want = np.clip(rt.offset_deg + rt.gain @ human, rt.low_deg, rt.high_deg)
    np.testing.assert_allclose(out, want)
    assert rt.apply(human, out=out) is out


def test_shape_errors_say_what_was_expected() -> None:
    rt = load_retarget(LEAP_TABLE)
    with pytest.raises(DataError, match="50 curves"):
        rt.apply(np.zeros(23))
    with pytest.raises(DataError, match="frames, 50"):
        rt.unclipped_many(np.zeros(50))
    with pytest.raises(KeyError, match="if_mcp"):
        rt.index("little_finger")


@pytest.mark.parametrize(("body", "match"), [
    ('[joints.a]\nsources = { riIndexMCP = 1.0 }\nrange_deg = [0.0, 1.0]\n',
     r"joints.a.sources.riIndexMCP.*unknown curve.*did you mean"),
    ('[joints.a]\nsources = { riWristFlexion = 1.0 }\nrange_deg = [0.0, 1.0]\n',
     r"joints.a.sources.riWristFlexion.*wrist DOF, not one of the 50 curves"),
    ('[joints.a]\nsources = { riIndexMCPy = 100.0 }\nrange_deg = [0.0, 1.0]\n',
     r"joints.a.sources.riIndexMCPy.*implausible gain"),
    ('[joints.a]\nrange_deg = [10.0, 1.0]\n', r"joints.a.range_deg.*inverted"),
    ('[joints.a]\nsources = { riIndexMCPy = 1.0 }\n', r"joints.a.range_deg.*missing"),
    ('[joints.a]\nrange_deg = [0.0, 1.0]\nscale = 2\n', r"joints.a.scale.*unknown key"),
])
def test_bad_tables_name_the_file_key_and_value(tmp_path: Path, body: str, match: str) -> None:
    p = _table(tmp_path, body)
    with pytest.raises(ConfigError, match=match) as info:
        load_retarget(p)
    assert str(p) in str(info.value)


def test_wrong_format_and_empty_table_are_refused(tmp_path: Path) -> None:
    p = tmp_path / "t.toml"
    p.write_text('format = "handrig-linear-map"\nversion = 1\n[joints.a]\nrange_deg = [0, 1]\n')
    with pytest.raises(ConfigError, match=r"format.*handrig-retarget"):
        load_retarget(p)
    p.write_text(HEADER + "[joints]\n")
    with pytest.raises(ConfigError, match="no robot joints"):
        load_retarget(p)


def test_check_against_model_names_unknown_joints_and_ranges_past_the_model() -> None:
    rt = load_retarget(LEAP_TABLE)
    joints = {n: MjcfJoint(n, "hinge", (-200.0, 200.0)) for n in rt.joint_names}
    rt.check_against_model(joints)
    missing = dict(joints)
    del missing["if_mcp"]
    missing["if_mcpp"] = MjcfJoint("if_mcpp", "hinge", None)
    with pytest.raises(ConfigError, match=r"joints.if_mcp.*did you mean 'if_mcpp'"):
        rt.check_against_model(missing)
    narrow = dict(joints, th_ipl=MjcfJoint("th_ipl", "hinge", (-10.0, 10.0)))
    with pytest.raises(ConfigError, match=r"joints.th_ipl.range_deg.*exceeds the model"):
        rt.check_against_model(narrow)


def test_check_joints_reports_ranges_flags_and_how_often_the_demo_is_clipped() -> None:
    gain = np.zeros((1, 50))
    gain[0, hand.curve_index("riIndexMCPy")] = 2.0
    rt = Retarget(("j",), gain, np.array([5.0]), np.array([0.0]), np.array([100.0]))
    low, high = np.full(50, -10.0), np.full(50, 10.0)
    demo = np.zeros((10, 50))
    demo[:, hand.curve_index("riIndexMCPy")] = np.arange(10) * 10.0 - 20.0  # -20 .. 70
    capture = np.zeros((3, 50))
    (c,) = check_joints(rt, low, high, capture, demo)
    assert c.anatomical_deg == (-15.0, 25.0)  # 5 + 2 x [-10, 10]
    assert c.capture_deg == (5.0, 5.0)
    assert c.demo_deg == (-35.0, 145.0)
    assert c.demo_low_frac == pytest.approx(0.2)  # -35, -15 below 0
    assert c.demo_high_frac == pytest.approx(0.3)  # 105, 125, 145 above 100
    assert c.flags == ("demo", "anatomy")
    (no_data,) = check_joints(rt, low, high)
    assert no_data.capture_deg is None and no_data.demo_deg is None
    assert no_data.demo_low_frac == 0.0


def test_the_leap_table_reads_the_little_finger_into_the_ring_finger() -> None:
    rt = load_retarget(LEAP_TABLE)
    for joint, curve in (("rf_mcp", "riPinkyMCPy"), ("rf_pip", "riPinkyPIPy"),
                         ("rf_dip", "riPinkyDIPy"), ("rf_rot", "riPinkyMCPx")):
        row = rt.gain[rt.index(joint)]
        assert np.flatnonzero(row).tolist() == [hand.curve_index(curve)], joint
    ring = [hand.curve_index(c.name) for c in hand.select_curves(hand="ri", digit="Ring")]
    assert not rt.gain[:, ring].any()  # the human ring finger drives nothing
    # side-to-side joints are positive toward the ulnar side: a negative gain on abduction
    assert rt.gain[rt.index("if_rot"), hand.curve_index("riIndexMCPx")] < 0.0
