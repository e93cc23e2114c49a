"""The MuJoCo puppet: servos drive the shared hand model's joints like X-series servos."""

from __future__ import annotations

import threading

import pytest

from firmware_protocol.dynamixel import Reg
from handrig.config.rig import RigConfig, ServoCalibration, load_rig_config
from handrig.devices.servo.positions import deg_to_ticks, ticks_to_deg
from sim.dxl_bus import servos_from_rig
from sim.dxl_servo import EmulatedServo
from sim.puppet import Puppet, kp_from_p_gain


def _setup(rig: RigConfig) -> tuple[Puppet, dict[int, EmulatedServo]]:
    puppet = Puppet(rig)
    servos = servos_from_rig(rig)
    puppet.attach(servos, threading.RLock())
    return puppet, {s.id: s for s in servos}


def _enable(servo: EmulatedServo, goal_ticks: int) -> None:
    assert servo.write(int(Reg.TORQUE_ENABLE), b"\x01") == 0
    assert servo.write(int(Reg.GOAL_POSITION), goal_ticks.to_bytes(4, "little")) == 0


def test_joints_follow_goals_and_present_state_comes_from_physics() -> None:
    rig = load_rig_config()
    puppet, servos = _setup(rig)
    goals = {}
    for cal in rig.servos:
        goals[cal.id] = deg_to_ticks(cal, cal.min_deg + 0.7 * (cal.max_deg - cal.min_deg))
        _enable(servos[cal.id], goals[cal.id])
    puppet.step(1000)  # 1 s of simulated time
    for cal in rig.servos:
        want = ticks_to_deg(cal, goals[cal.id])
        got = puppet.joint_deg(cal.joint)
        tol = 12.0 if "Wrist" in cal.joint else 2.0
        assert abs(got - want) < tol, (cal.joint, want, got)
        # Present Position is the simulated angle mapped back through the calibration
        assert abs(ticks_to_deg(cal, servos[cal.id].present) - got) < 0.1
    # holding a finger against gravity takes current; the drooping wrist takes more
    wrist = next(c for c in rig.servos if c.joint == "riWristFlexion")
    held = servos[wrist.id]
    assert abs(held.get(Reg.PRESENT_CURRENT)) * held.info.current_unit_ma > 50  # mA


def test_speed_limit_from_profile_velocity() -> None:
    cal = ServoCalibration(id=1, joint="riIndexPIPy", min_deg=0.0, max_deg=100.0)
    puppet, servos = _setup(RigConfig(servos=(cal,)))
    s = servos[1]
    assert s.write(int(Reg.PROFILE_VELOCITY), (20).to_bytes(4, "little")) == 0  # 4.58 rpm
    _enable(s, deg_to_ticks(cal, 90.0))
    puppet.step(200)
    deg_per_s = 20 * 0.229 * 6.0  # rpm -> deg/s
    assert puppet.joint_deg("riIndexPIPy") == pytest.approx(0.2 * deg_per_s, abs=2.0)
    assert s.get(Reg.PRESENT_VELOCITY) == pytest.approx(20, abs=3)


def test_torque_off_lets_gravity_win_and_torque_limit_holds() -> None:
    cal = ServoCalibration(id=4, joint="riWristFlexion", min_deg=-60.0, max_deg=60.0)
    puppet, servos = _setup(RigConfig(servos=(cal,)))
    s = servos[4]
    puppet.step(500)
    sagged = puppet.joint_deg("riWristFlexion")
    assert sagged > 20.0  # palm down: the hand falls into flexion
    # current-based position mode with a tiny Goal Current cannot lift the hand
    assert s.write(int(Reg.OPERATING_MODE), b"\x05") == 0
    assert s.write(int(Reg.GOAL_CURRENT), (30).to_bytes(2, "little")) == 0
    _enable(s, deg_to_ticks(cal, 0.0))
    puppet.step(500)
    assert puppet.joint_deg("riWristFlexion") > 20.0
    assert abs(s.get(Reg.PRESENT_CURRENT)) <= 31
    # full current lifts it most of the way
    assert s.write(int(Reg.GOAL_CURRENT), (1750).to_bytes(2, "little")) == 0
    puppet.step(500)
    assert puppet.joint_deg("riWristFlexion") < 15.0


def test_kp_from_p_gain() -> None:
    # P 400 on an XL330 (0.52 N m stall): PWM saturates at 885 / (400/128) = 283 ticks
    assert kp_from_p_gain(400, 0.52) == pytest.approx(0.52 / (283.2 * 2 * 3.14159265 / 4096),
                                                      rel=1e-3)


def test_realtime_thread_never_runs_ahead_and_reports_falling_behind() -> None:
    import time

    rig = load_rig_config()
    behind: list[float] = []
    # allowed lag of one step but woken every 5 ms: it must fall behind and say so
    puppet = Puppet(rig, period_s=0.005, max_lag_s=0.001, on_behind=behind.append)
    puppet.attach(servos_from_rig(rig), threading.RLock())
    t0 = time.perf_counter()
    puppet.start()
    try:
        time.sleep(0.2)
    finally:
        puppet.stop()
    elapsed = time.perf_counter() - t0
    assert puppet.error is None
    assert 0.0 < puppet.sim_time_s <= elapsed
    assert puppet.behind_count == len(behind) > 0
    assert puppet.behind_total_s == pytest.approx(sum(behind))


def test_gravity_direction_changes_the_sag() -> None:
    cal = ServoCalibration(id=4, joint="riWristFlexion", min_deg=-60.0, max_deg=60.0)
    puppet, _ = _setup(RigConfig(servos=(cal,)))
    puppet.set_gravity((0.0, 0.0, 9.81))  # palm up: the unpowered hand falls into extension
    puppet.step(500)
    assert puppet.joint_deg("riWristFlexion") < -20.0


def test_held_at_torque_limit_reports_overload_only_when_enabled() -> None:
    cal = ServoCalibration(id=4, joint="riWristFlexion", min_deg=-60.0, max_deg=60.0)
    for overload_s, expect in ((None, 0), (0.3, 0x20)):
        puppet = Puppet(RigConfig(servos=(cal,)), overload_s=overload_s)
        (s,) = servos_from_rig(RigConfig(servos=(cal,)))
        puppet.attach([s], threading.RLock())
        # 20 mA of Goal Current cannot lift the sagging hand: the servo sits at its limit
        assert s.write(int(Reg.POSITION_P_GAIN), (4000).to_bytes(2, "little")) == 0
        assert s.write(int(Reg.OPERATING_MODE), b"\x05") == 0
        assert s.write(int(Reg.GOAL_CURRENT), (20).to_bytes(2, "little")) == 0
        puppet.step(300)
        _enable(s, deg_to_ticks(cal, -50.0))
        puppet.step(600)
        assert s.hardware_error == expect
        assert s.torque_enabled == (expect == 0)


def test_from_rig_extra_ids_move_kinematically_and_model_override_reaches_the_puppet() -> None:
    import time

    from sim.dxl_bus import SimBus

    rig = load_rig_config()
    ids = [s.id for s in rig.servos] + [30]
    with SimBus.from_rig(rig, ids=ids, model="XM430-W350", puppet=True) as bus:
        assert bus.puppet is not None
        assert sorted(bus.puppet.driven_ids) == sorted(s.id for s in rig.servos)
        assert {s.info.name for s in bus.servos} == {"XM430-W350"}
        assert isinstance(bus.puppet, Puppet)
        hand = bus.puppet.hands["ri"]
        # XM430-W350 stall torque 4.1 N m sets the actuators' force range
        assert max(hand.model.actuator_forcerange[:, 1]) == pytest.approx(4.1)
        extra = bus.servo(30)
        with bus.lock:
            _enable(extra, 2500)
        end = time.monotonic() + 2.0
        while extra.present != 2500 and time.monotonic() < end:
            time.sleep(0.01)
        assert extra.present == 2500
