"""Robot rigs: the LEAP preset, its servo settings, and every cross-check against the model."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from handrig.config.loading import REPO_ROOT, build
from handrig.config.rig import RigConfig, ServoSettings, load_rig_config
from handrig.config.rig_files import RIGS_DIR
from handrig.config.rig_files import rig_file_path as rig_path
from handrig.devices.servo.models import (
    OPERATING_MODES,
    check_rig,
    current_limit_units,
    servo_settings_for,
)
from handrig.devices.servo.positions import deg_to_ticks
from handrig.errors import ConfigError
from handrig.pose.mjcf import read_joints
from handrig.pose.robot_rig import (
    RobotRigConfig,
    load_rig,
    load_robot_rig,
    render_view,
    robot_retarget,
)

LEAP_RIG = RIGS_DIR / "leap.toml"
LEAP_MODEL = REPO_ROOT / "data" / "robots" / "leap_hand" / "right_hand.xml"
# The LEAP hand API's numbering: per finger side-to-side, MCP, PIP, DIP; thumb last.
LEAP_IDS = ["if_rot", "if_mcp", "if_pip", "if_dip", "mf_rot", "mf_mcp", "mf_pip", "mf_dip",
            "rf_rot", "rf_mcp", "rf_pip", "rf_dip", "th_cmc", "th_axl", "th_mcp", "th_ipl"]


def test_leap_preset_is_sixteen_xc330s_at_4_mbps_with_sag_off() -> None:
    rig = load_rig("leap")
    assert isinstance(rig, RobotRigConfig) and rig.robot is not None
    assert rig.bus.baud == 4_000_000
    assert [s.id for s in rig.servos] == list(range(16))
    assert [s.joint for s in rig.servos] == LEAP_IDS
    assert {s.model for s in rig.servos} == {"XC330-M288"}  # 5 V, model number 1240
    assert {(s.zero_ticks, s.direction) for s in rig.servos} == {(2048, 1)}
    assert Path(rig.robot.model) == LEAP_MODEL.resolve()
    assert rig.robot.sag is False and rig.effective_sag_gain == 0.0
    # the human rig keeps its sag
    assert load_rig_config().effective_sag_gain == 1.0


def test_leap_servo_settings_are_the_leap_api_values() -> None:
    rig = load_rig("leap")
    for s in rig.servos:
        st = servo_settings_for(rig, s.id)
        assert st.operating_mode == 5  # current-based position
        assert st.current_limit_ma == 350
        assert current_limit_units(st.current_limit_ma, s.model) == 350
        assert st.return_delay_us == 0
        side = s.joint.endswith("_rot")
        assert (st.position_p_gain, st.position_d_gain) == ((450, 150) if side else (600, 200))
    # a human rig writes position mode and leaves current and gains alone
    st = servo_settings_for(load_rig_config(), 1)
    assert (st.operating_mode, st.current_limit_ma, st.position_p_gain) == (3, None, None)


def test_leap_rig_and_retarget_table_agree_with_the_model_joints_and_ranges() -> None:
    mujoco = pytest.importorskip("mujoco")
    rig = load_rig("leap")
    model = mujoco.MjModel.from_xml_path(str(LEAP_MODEL))
    compiled = {}
    for j in range(model.njnt):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        compiled[name] = tuple(math.degrees(v) for v in model.jnt_range[j])
    # the XML reader sees what MuJoCo compiles
    parsed = read_joints(LEAP_MODEL)
    assert set(parsed) == set(compiled)
    for name, j in parsed.items():
        assert j.range == pytest.approx(compiled[name], abs=1e-9)
    # every servo on a model joint, limits within the joint's range, rounded by < 0.1 deg
    assert {s.joint for s in rig.servos} == set(compiled)
    for s in rig.servos:
        low, high = compiled[s.joint]
        assert low <= s.min_deg < low + 0.1 and high - 0.1 < s.max_deg <= high, s.joint
        assert 0 <= deg_to_ticks(s, s.min_deg) < deg_to_ticks(s, s.max_deg) <= 4095
    rt = robot_retarget(rig)
    assert set(rt.joint_names) == set(compiled)
    for k, name in enumerate(rt.joint_names):
        servo = next(s for s in rig.servos if s.joint == name)
        assert (rt.low_deg[k], rt.high_deg[k]) == (servo.min_deg, servo.max_deg)


def _write_rig(tmp_path: Path, edit: str = "", old: str = "", table_edit: tuple[str, str] | None
               = None) -> Path:
    """A copy of the LEAP preset in tmp_path (model path made absolute), edited."""
    text = LEAP_RIG.read_text().replace("../../data/robots/leap_hand/right_hand.xml",
                                        str(LEAP_MODEL))
    if old:
        assert old in text, old
        text = text.replace(old, edit, 1)
    table = (RIGS_DIR / "leap_retarget.toml").read_text()
    if table_edit is not None:
        assert table_edit[0] in table
        table = table.replace(*table_edit, 1)
    (tmp_path / "leap_retarget.toml").write_text(table)
    p = tmp_path / "rig.toml"
    p.write_text(text)
    return p


def test_a_copy_of_the_preset_loads_with_paths_relative_to_it(tmp_path: Path) -> None:
    rig = load_robot_rig(_write_rig(tmp_path))
    assert rig.robot is not None
    assert Path(rig.robot.retarget) == (tmp_path / "leap_retarget.toml").resolve()
    switched = load_robot_rig(_write_rig(tmp_path, "sag = true", "sag = false"))
    assert switched.effective_sag_gain == 1.0
    # --render looks at LEAP from its palm's side; a rig without render_view: the default
    assert render_view(rig) == (0.40, 30.0, -35.0)
    plain = load_robot_rig(_write_rig(tmp_path, "", "render_view = [0.40, 30.0, -35.0]"))
    assert render_view(plain) is None and render_view(load_rig_config()) is None


@pytest.mark.parametrize(("old", "new", "match"), [
    ('joint = "if_mcp"', 'joint = "if_mpc"', r"servos\[1\].joint.*'if_mpc'.*did you mean 'if_mcp'"),
    ('joint = "if_mcp"', 'joint = "riIndexMCPy"', r"servos\[1\].joint.*human curve"),
    ("id = 1\n", "id = 0\n", r"servos\[1\].id.*used twice"),
    ("max_deg = 127.7", "max_deg = 140.0",
     r"servos\[1\].max_deg.*140.0.*exceeds the model's range of if_mcp"),
    ("ids = [0, 4, 8]", "ids = [0, 4, 16]", r"servo_settings.groups\[0\].ids.*= 16.*no servo"),
    ("return_delay_us = 0", "return_delay_us = 3", r"return_delay_us.*= 3.*steps of 2"),
    ('operating_mode = "current_based_position"', 'operating_mode = "current"',
     r"operating_mode.*'current'.*current_based_position"),
    ("position_p_gain = 600", "position_p_gain = 20000", r"position_p_gain.*gain out of range"),
    ('retarget = "leap_retarget.toml"', 'retarget = "missing.toml"', r"missing.toml.*not found"),
    ("render_view = [0.40, 30.0, -35.0]", "render_view = [30.0, -35.0]",
     r"render_view.*\[30.0, -35.0\].*distance m"),
    ("render_view = [0.40, 30.0, -35.0]", "render_view = [0.4, 30.0, -135.0]",
     r"render_view.*elevation deg"),
])
def test_bad_robot_rigs_name_file_key_value(tmp_path: Path, old: str, new: str,
                                           match: str) -> None:
    p = _write_rig(tmp_path, new, old)
    with pytest.raises(ConfigError, match=match):  # on load, or by the driver's check
        check_rig(load_rig(p), str(p))


def test_a_current_limit_above_the_models_is_refused_by_the_drivers_check(
        tmp_path: Path) -> None:
    """A rig file names its servos' models as strings; what each model takes is the
    driver's table (devices/servo/models.py), checked before the bus opens."""
    p = _write_rig(tmp_path, "current_limit_ma = 2400", "current_limit_ma = 350")
    rig = load_rig(p)
    with pytest.raises(ConfigError, match=r"current_limit_ma.*2400.*above the XC330-M288's "
                       "maximum"):
        check_rig(rig, str(p))


def test_retarget_table_must_cover_every_servo_and_stay_within_the_model(tmp_path: Path) -> None:
    p = _write_rig(tmp_path, table_edit=("[joints.th_ipl]", "[joints.th_ipl_x]"))
    with pytest.raises(ConfigError, match=r"leap_retarget.toml.*joints.th_ipl_x.*no such hinge"):
        load_rig(p)
    p = _write_rig(tmp_path, table_edit=("range_deg = [-76.7, 107.7]", "range_deg = [-90, 107.7]"))
    with pytest.raises(ConfigError, match=r"joints.th_ipl.range_deg.*exceeds the model's"):
        load_rig(p)


def test_presets_by_name_and_unknown_names(tmp_path: Path) -> None:
    assert rig_path("leap") == LEAP_RIG
    assert rig_path(None).name == "rig.toml"
    with pytest.raises(ConfigError, match=r"no rig preset 'leapp'.*leap"):
        rig_path("leapp")
    human = load_rig(None)
    assert type(human) is RigConfig and human.servos[0].joint == "riThumbCMCx"


def test_servo_settings_parse_with_defaults_and_groups() -> None:
    s = build(ServoSettings, {})
    assert (OPERATING_MODES[s.operating_mode], s.return_delay_us, s.groups) == (3, 0, ())
    with pytest.raises(ConfigError, match=re.escape("groups[1].ids") + r".*in two groups"):
        build(ServoSettings, {"groups": [{"ids": [1, 2]}, {"ids": [2]}]})
    with pytest.raises(ConfigError, match=r"groups\[0\].ids.*at least one"):
        build(ServoSettings, {"groups": [{"ids": []}]})


def test_mjcf_reader_resolves_classes_and_degrees_and_names_bad_files(tmp_path: Path) -> None:
    p = tmp_path / "m.xml"
    p.write_text("""<mujoco><default><joint range="-10 10"/>
      <default class="big"><joint range="-90 90"/></default></default>
      <worldbody><body childclass="big"><joint name="a"/>
        <body><joint name="b" class="main"/><joint name="c" range="0 5" limited="false"/>
          <joint name="s" type="slide" range="0 0.1"/><joint name="f" type="free"/></body>
      </body></worldbody></mujoco>""")
    joints = read_joints(p)
    assert list(joints) == ["a", "b", "c", "s"]
    assert joints["a"].range == (-90.0, 90.0) and joints["b"].range == (-10.0, 10.0)
    assert joints["c"].range is None and joints["s"].type == "slide"
    p.write_text("<mujoco><worldbody>")
    with pytest.raises(ConfigError, match="cannot read the MJCF"):
        read_joints(p)
    with pytest.raises(ConfigError, match="MJCF model not found"):
        read_joints(tmp_path / "none.xml")
