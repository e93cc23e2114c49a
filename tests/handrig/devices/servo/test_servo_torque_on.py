"""Torque-on never moves a servo that sits outside its limits."""

from __future__ import annotations

import time

import pytest

from firmware_protocol.dynamixel import Reg
from handrig.config.rig import RigConfig, load_rig_config
from handrig.devices.servo import DynamixelBus
from handrig.errors import DeviceError
from sim.dxl_bus import SimBus
from sim.dxl_servo import EmulatedServo


def _rig() -> RigConfig:
    rig = load_rig_config()
    return RigConfig(bus=rig.bus, loop=rig.loop, servos=(rig.servo(7), rig.servo(8)))


def _servos(pip_ticks: float) -> list[EmulatedServo]:
    # servo 8 drives riIndexPIPy: limits 0..110 deg, zero 2048, direction +1
    return [EmulatedServo(7, start_ticks=2048.0), EmulatedServo(8, start_ticks=pip_ticks)]


def test_torque_on_brings_a_slightly_outside_servo_in_slowly():
    below = 2048 - 6 * 4096 / 360  # -6 deg: a limp finger resting past its stop
    with SimBus(_servos(below)) as sim:
        bus = DynamixelBus(sim.port_path, _rig())
        bus.connect()
        try:
            t0 = time.monotonic()
            with bus.torque(handle_signals=False):
                took = time.monotonic() - t0
                assert sim.servo(8).goal == 2048  # the limit (0 deg), never beyond
                assert abs(sim.servo(8).present - 2048) <= 12  # within the 1 deg slack
                assert sim.servo(8).get(Reg.PROFILE_VELOCITY) == 0  # speed limit lifted again
            # 5 deg (6 out, 1 of slack) at about 30 deg/s, not at full speed (a few ms):
            # Profile Velocity rounds to 0.229 rpm units, 22 of them are 30.2 deg/s
            assert took > 0.9 * 5 / 30.0
            assert any("brought in at 30 deg/s" in line for line in bus.commissioning)
        finally:
            bus.close()


def test_torque_on_refuses_a_servo_far_outside_its_limits():
    below = 2048 - 40 * 4096 / 360  # -40 deg: a wrong zero
    with SimBus(_servos(below)) as sim:
        bus = DynamixelBus(sim.port_path, _rig())
        bus.connect()
        try:
            expected = r"servo 8 \(riIndexPIPy\) is at -40.0 deg, outside its limits \[0, 110\]"
            with pytest.raises(DeviceError, match=expected), bus.torque(handle_signals=False):
                pass
        finally:
            bus.close()
        assert not sim.servo(8).torque_enabled and not sim.servo(7).torque_enabled
        assert abs(sim.servo(8).present - below) < 2


def test_calibration_holds_an_outside_servo_where_it_is():
    below = 2048 - 40 * 4096 / 360
    with SimBus(_servos(below)) as sim:
        bus = DynamixelBus(sim.port_path, _rig())
        bus.hold_outside_limits = True
        bus.connect()
        try:
            with bus.torque(handle_signals=False):
                time.sleep(0.2)
                assert sim.servo(8).torque_enabled
                assert abs(sim.servo(8).goal - below) <= 1
                assert abs(sim.servo(8).present - below) < 2
        finally:
            bus.close()


def test_an_approach_that_does_not_arrive_is_an_error_and_leaves_no_speed_limit():
    below = 2048 - 6 * 4096 / 360
    with SimBus(_servos(below)) as sim:
        sim.servo(8).set(Reg.VELOCITY_LIMIT, 1)  # 0.229 rpm: far too slow to arrive in time
        bus = DynamixelBus(sim.port_path, _rig())
        bus.connect()
        try:
            with pytest.raises(DeviceError, match=r"servo 8 \(riIndexPIPy\) did not come into"
                                                  r" its limits"), \
                    bus.torque(handle_signals=False):
                pass
        finally:
            bus.close()
        assert not sim.servo(8).torque_enabled
        assert sim.servo(8).get(Reg.PROFILE_VELOCITY) == 0


def test_torque_on_clears_a_speed_limit_left_by_an_earlier_crash():
    with SimBus(_servos(2048.0)) as sim:
        sim.servo(7).set(Reg.PROFILE_VELOCITY, 22)  # what a run that died mid-approach leaves
        bus = DynamixelBus(sim.port_path, _rig())
        bus.connect()
        try:
            with bus.torque(handle_signals=False):
                assert sim.servo(7).get(Reg.PROFILE_VELOCITY) == 0
        finally:
            bus.close()
