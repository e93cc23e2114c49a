"""One emulated X-series servo: control-table rules and instruction semantics."""

from __future__ import annotations

import itertools
import math

import pytest

from firmware_protocol.dynamixel import ERROR_ALERT, MODELS, ErrorCode, HardwareError, Reg
from sim.dxl_servo import REBOOT_S, EmulatedServo
from sim.dxl_thermal import (
    AMBIENT_TEMPERATURE_C,
    THERMAL,
    idle_temperature_c,
    steady_temperature_c,
)


def _w(servo: EmulatedServo, reg: Reg, value: int, size: int, signed: bool = False) -> int:
    return servo.write(int(reg), value.to_bytes(size, "little", signed=signed))


def test_ping_and_identity() -> None:
    s = EmulatedServo(7, "XM430-W350")
    err, data = s.ping()
    assert err == 0 and data == (1020).to_bytes(2, "little") + bytes((46,))
    assert s.get(Reg.ID) == 7 and s.id == 7
    assert s.get(Reg.RETURN_DELAY_TIME) == 250 and s.return_delay_s == 250 * 2e-6


def test_eeprom_needs_torque_off_and_read_only_refuses() -> None:
    s = EmulatedServo(1)
    assert _w(s, Reg.TORQUE_ENABLE, 1, 1) == 0
    assert _w(s, Reg.OPERATING_MODE, 4, 1) == ErrorCode.ACCESS
    assert _w(s, Reg.TORQUE_ENABLE, 0, 1) == 0
    assert _w(s, Reg.OPERATING_MODE, 4, 1) == 0
    assert s.get(Reg.OPERATING_MODE) == 4
    assert _w(s, Reg.PRESENT_POSITION, 0, 4) == ErrorCode.ACCESS
    assert _w(s, Reg.MODEL_NUMBER, 1, 2) == ErrorCode.ACCESS
    assert s.write(66, b"\x00") == ErrorCode.ACCESS  # undefined address
    assert s.write(117, b"\x00\x00") == ErrorCode.DATA_LENGTH  # inside Goal Position
    assert _w(s, Reg.OPERATING_MODE, 2, 1) == ErrorCode.DATA_RANGE
    assert _w(s, Reg.TORQUE_ENABLE, 2, 1) == ErrorCode.DATA_RANGE


def test_goal_position_limits_and_multi_item_write() -> None:
    s = EmulatedServo(1)
    assert _w(s, Reg.MIN_POSITION_LIMIT, 1000, 4) == 0
    assert _w(s, Reg.MAX_POSITION_LIMIT, 3000, 4) == 0
    assert _w(s, Reg.GOAL_POSITION, 999, 4) == ErrorCode.DATA_LIMIT
    assert _w(s, Reg.GOAL_POSITION, 3001, 4) == ErrorCode.DATA_LIMIT
    assert _w(s, Reg.GOAL_POSITION, 2500, 4) == 0 and s.goal == 2500
    # Profile Acceleration + Profile Velocity in one write (8 bytes at 108)
    assert s.write(108, (10).to_bytes(4, "little") + (50).to_bytes(4, "little")) == 0
    assert s.get(Reg.PROFILE_VELOCITY) == 50
    # in extended position mode the limits do not apply
    assert _w(s, Reg.OPERATING_MODE, 4, 1) == 0
    assert _w(s, Reg.GOAL_POSITION, -5000, 4, signed=True) == 0


def test_kinematic_motion_at_speed_limit_and_only_with_torque() -> None:
    s = EmulatedServo(1)
    assert _w(s, Reg.GOAL_POSITION, 3048, 4) == 0
    s.advance(0.05)
    assert s.present == 2048  # torque off: no motion
    assert _w(s, Reg.TORQUE_ENABLE, 1, 1) == 0
    s.advance(0.05)
    speed = 445 * 0.229 * 4096 / 60  # XL330-M288 Velocity Limit default, ticks/s
    assert 2048 + 0.05 * speed - 2 <= s.present <= 2048 + 0.05 * speed + 2
    assert s.get(Reg.PRESENT_VELOCITY) > 0 and s.get(Reg.MOVING) == 1
    s.advance(1.0)
    assert s.present == 3048


def test_homing_offset_and_reverse_drive_mode() -> None:
    s = EmulatedServo(1, start_ticks=1000)
    assert s.present == 1000
    assert _w(s, Reg.HOMING_OFFSET, -200, 4, signed=True) == 0
    assert s.present == 800
    assert _w(s, Reg.DRIVE_MODE, 1, 1) == 0
    assert s.present == -1000 - 200
    # the goal is read back through the same mapping: motor position 1500
    assert _w(s, Reg.OPERATING_MODE, 4, 1) == 0
    assert _w(s, Reg.GOAL_POSITION, -1700, 4, signed=True) == 0
    assert s.goal_motor_ticks() == 1500


def test_overload_sets_alert_keeps_torque_off_until_reboot() -> None:
    s = EmulatedServo(1)
    assert _w(s, Reg.TORQUE_ENABLE, 1, 1) == 0
    s.inject_hardware_error(HardwareError.OVERLOAD, persistent=True)
    assert not s.torque_enabled
    assert s.hardware_error == HardwareError.OVERLOAD
    err, _ = s.ping()
    assert err == ERROR_ALERT
    assert _w(s, Reg.TORQUE_ENABLE, 1, 1) == ERROR_ALERT and not s.torque_enabled
    s.reboot(now=10.0)  # cause still there: the error comes back
    assert s.hardware_error == HardwareError.OVERLOAD
    s.clear_injected_fault()
    s.reboot(now=10.0)
    assert s.hardware_error == 0 and not s.available(10.0) and s.available(10.0 + REBOOT_S)
    assert _w(s, Reg.TORQUE_ENABLE, 1, 1) == 0


def test_reg_write_action_and_instruction_error() -> None:
    s = EmulatedServo(1)
    assert s.action() == ErrorCode.INSTRUCTION
    assert s.reg_write(int(Reg.GOAL_POSITION), (3000).to_bytes(4, "little")) == 0
    assert s.goal == 2048 and s.get(Reg.REGISTERED_INSTRUCTION) == 1
    assert s.action() == 0
    assert s.goal == 3000 and s.get(Reg.REGISTERED_INSTRUCTION) == 0


def test_reboot_resets_ram_and_factory_reset_options() -> None:
    s = EmulatedServo(5)
    assert _w(s, Reg.RETURN_DELAY_TIME, 0, 1) == 0
    assert _w(s, Reg.STATUS_RETURN_LEVEL, 1, 1) == 0
    assert _w(s, Reg.TORQUE_ENABLE, 1, 1) == 0
    s.reboot(now=0.0)
    assert s.status_return_level == 2 and not s.torque_enabled
    assert s.get(Reg.RETURN_DELAY_TIME) == 0  # EEPROM survives a reboot
    assert s.factory_reset(0x02, now=0.0) == 0
    assert s.id == 5 and s.get(Reg.RETURN_DELAY_TIME) == 250
    assert s.factory_reset(0xFF, now=0.0) == 0
    assert s.id == 1 and s.get(Reg.BAUD_RATE) == 1
    assert s.factory_reset(0x07, now=0.0) == ErrorCode.DATA_RANGE


def test_bus_watchdog_stops_servo_and_refuses_goals_until_cleared() -> None:
    s = EmulatedServo(1)
    assert _w(s, Reg.BUS_WATCHDOG, 5, 1) == 0  # 100 ms
    assert _w(s, Reg.TORQUE_ENABLE, 1, 1) == 0
    s.last_heard = 0.0
    assert not s.check_watchdog(0.09)
    assert s.check_watchdog(0.11)
    assert s.get(Reg.BUS_WATCHDOG) == -1
    assert _w(s, Reg.GOAL_POSITION, 2100, 4) == ErrorCode.DATA_RANGE
    assert _w(s, Reg.BUS_WATCHDOG, 0, 1) == 0
    assert _w(s, Reg.GOAL_POSITION, 2100, 4) == 0


def test_reads() -> None:
    s = EmulatedServo(1)
    err, data = s.read(132, 4)
    assert err == 0 and int.from_bytes(data, "little") == 2048
    err, data = s.read(0, 147)  # the whole table in one read
    assert err == 0 and len(data) == 147
    assert s.read(600, 100) == (ErrorCode.ACCESS, b"")


def test_one_shot_overload_is_cleared_by_reboot() -> None:
    s = EmulatedServo(1)
    s.inject_hardware_error()
    assert s.hardware_error == HardwareError.OVERLOAD
    assert _w(s, Reg.TORQUE_ENABLE, 1, 1) == ERROR_ALERT
    s.reboot(now=0.0)
    assert s.hardware_error == 0 and s.ping()[0] == 0


def test_current_heats_the_motor_and_overheating_stops_it() -> None:
    s = EmulatedServo(1)
    assert s.get(Reg.PRESENT_TEMPERATURE) == 30
    assert _w(s, Reg.TORQUE_ENABLE, 1, 1) == 0
    s.set_motion(2048.0, 0.0, 1000.0)  # 1 A: 3.4 ohm x 1 A^2 x 25 K/W = 85 K above ambient
    for _ in range(100):
        s.heat(60.0)
    assert s.hardware_error & HardwareError.OVERHEATING
    assert not s.torque_enabled and s.get(Reg.PRESENT_TEMPERATURE) > 70
    s.set_motion(2048.0, 0.0, 0.0)
    for _ in range(100):
        s.heat(60.0)
    assert s.get(Reg.PRESENT_TEMPERATURE) == round(idle_temperature_c("XL330-M288", 5.0)) == 32


def test_temperature_follows_the_current_over_minutes() -> None:
    s = EmulatedServo(1)  # XL330 at 5 V: 3.4 ohm winding
    s.set_motion(2048.0, 0.0, 300.0)
    temps = []
    for _ in range(60):
        s.heat(1.0)
        temps.append(s.temperature_c)
    assert all(b > a for a, b in itertools.pairwise(temps))  # rising with current
    target = steady_temperature_c("XL330-M288", 5.0, 0.3)
    tau = THERMAL["XL330-M288"].time_constant_s
    assert temps[-1] == pytest.approx(30 + (target - 30) * (1 - math.exp(-60.0 / tau)), rel=1e-6)
    assert s.get(Reg.PRESENT_TEMPERATURE) == round(temps[-1]) > 30


def _hold(model: str, fraction_of_stall: float, seconds: float) -> EmulatedServo:
    """A servo of ``model`` at its nominal voltage holding ``fraction_of_stall`` of its
    stall current for ``seconds`` (torque on), heated in 1 s steps."""
    s = EmulatedServo(1, model)
    assert _w(s, Reg.TORQUE_ENABLE, 1, 1) == 0
    s.set_motion(2048.0, 0.0, fraction_of_stall * s.info.stall_current_a * 1000.0)
    for _ in range(int(seconds)):
        s.heat(1.0)
    return s


@pytest.mark.parametrize("model", sorted(MODELS))
def test_each_model_runs_for_an_hour_at_the_continuous_torque(model: str) -> None:
    """ROBOTIS: a servo rated by stall torque runs continuously at about 20 % of it
    (docs/hardware.md, "Heat"): an hour there stays 10 K under the Temperature Limit."""
    s = _hold(model, 0.20, 3600)
    limit = s.get(Reg.TEMPERATURE_LIMIT)
    assert s.hardware_error == 0 and s.torque_enabled
    assert AMBIENT_TEMPERATURE_C + 5 < s.temperature_c < limit - 10, (model, s.temperature_c)


@pytest.mark.parametrize("model", sorted(MODELS))
def test_each_model_stalled_reaches_its_limit_within_minutes(model: str) -> None:
    """At stall current every model overheats and turns torque off, in 30 s to 6 min:
    the climb is a matter of minutes, which a read every second sees coming."""
    s = EmulatedServo(1, model)
    assert _w(s, Reg.TORQUE_ENABLE, 1, 1) == 0
    s.set_motion(2048.0, 0.0, s.info.stall_current_a * 1000.0)
    t = 0
    while not s.hardware_error and t < 3600:
        s.heat(1.0)
        t += 1
    assert s.hardware_error & HardwareError.OVERHEATING and not s.torque_enabled
    assert 30 <= t <= 360, (model, t)


@pytest.mark.parametrize("model", sorted(MODELS))
def test_each_model_thermal_figures_come_from_its_datasheet(model: str) -> None:
    spec, info = THERMAL[model], MODELS[model]
    small = model.startswith(("XL330", "XC330"))
    assert spec.size_mm == ((20.0, 34.0, 26.0) if small else (28.5, 46.5, 34.0))
    assert 0.015 <= spec.standby_current_a <= 0.05
    assert (20.0 if small else 12.0) <= spec.resistance_k_per_w <= (30.0 if small else 20.0)
    assert (300.0 if small else 600.0) <= spec.time_constant_s <= (600.0 if small else 1500.0)
    assert info.stall_current_a > 0 and info.nominal_voltage_dv > 0


def test_an_xl330_at_a_modest_hold_climbs_a_few_kelvin_in_a_minute_not_thirty() -> None:
    """Issue 24.3: 30 % of stall (0.44 A) for 60 s warmed the old model by ~23 K."""
    s = _hold("XL330-M288", 0.30, 60)
    assert 1.0 < s.temperature_c - AMBIENT_TEMPERATURE_C < 5.0, s.temperature_c
    # and it settles under the limit: a servo at 30 % of stall can run a show
    assert steady_temperature_c("XL330-M288", 5.0, 0.30 * 1.47) < 60.0


def test_current_based_position_mode_caps_current_at_goal_current_and_current_limit() -> None:
    s = EmulatedServo(3, "XC330-T288")
    assert s.current_cap_ma() is None  # position mode: only the stall current bounds it
    assert s.get(Reg.GOAL_CURRENT) == s.get(Reg.CURRENT_LIMIT) == 910  # starts at the limit
    assert _w(s, Reg.OPERATING_MODE, 5, 1) == 0
    assert s.operating_mode == 5 and s.current_cap_ma() == 910.0
    assert _w(s, Reg.CURRENT_LIMIT, 350, 2) == 0  # below the Goal Current already set
    assert s.current_cap_ma() == 350.0
    assert _w(s, Reg.GOAL_CURRENT, 351, 2, signed=True) == ErrorCode.DATA_LIMIT
    assert _w(s, Reg.GOAL_CURRENT, -200, 2, signed=True) == 0
    assert s.current_cap_ma() == 200.0  # the magnitude counts
    # after a reboot Goal Current is back at the (kept, EEPROM) Current Limit
    s.reboot(0.0)
    assert s.get(Reg.GOAL_CURRENT) == 350 and s.current_cap_ma() == 350.0
    xm = EmulatedServo(4, "XM430-W350")
    assert _w(xm, Reg.OPERATING_MODE, 5, 1) == 0
    assert xm.current_cap_ma() == 1193 * 2.69  # XM430 counts 2.69 mA per unit
