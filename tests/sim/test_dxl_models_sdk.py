"""Each servo model as a plain dynamixel-sdk client sees it: ranges and defaults from
its e-manual table, Moving Status, Present PWM, the trajectory registers and the
hardware errors."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

from firmware_protocol.dynamixel import MODELS, ErrorCode, HardwareError, Reg
from sim.dxl_bus import SimBus
from sim.dxl_servo import EmulatedServo

ERR_MASK = 0x7F


@pytest.fixture
def line() -> Iterator[tuple[SimBus, PortHandler, PacketHandler]]:
    servos = [EmulatedServo(i + 1, name) for i, name in enumerate(MODELS)]
    with SimBus(servos) as bus:
        port = PortHandler(bus.port_path)
        assert port.openPort() and port.setBaudRate(1_000_000)
        try:
            yield bus, port, PacketHandler(2.0)
        finally:
            port.closePort()


def _id(model: str) -> int:
    return list(MODELS).index(model) + 1


def test_current_limit_2352_xc330_m288_yes_xc330_t288_no(
    line: tuple[SimBus, PortHandler, PacketHandler],
) -> None:
    _, port, ph = line
    m288, t288 = _id("XC330-M288"), _id("XC330-T288")
    assert ph.read2ByteTxRx(port, m288, Reg.CURRENT_LIMIT) == (2352, COMM_SUCCESS, 0)
    assert ph.read2ByteTxRx(port, t288, Reg.CURRENT_LIMIT) == (910, COMM_SUCCESS, 0)
    assert ph.write2ByteTxRx(port, m288, Reg.CURRENT_LIMIT, 2352) == (COMM_SUCCESS, 0)
    result, err = ph.write2ByteTxRx(port, t288, Reg.CURRENT_LIMIT, 2352)
    assert result == COMM_SUCCESS and err & ERR_MASK == ErrorCode.DATA_RANGE
    assert ph.read2ByteTxRx(port, t288, Reg.CURRENT_LIMIT)[0] == 910  # nothing written
    # the XM430's table stops at 1193 (units of 2.69 mA); the XC430 has no such item
    xm = _id("XM430-W350")
    assert ph.write2ByteTxRx(port, xm, Reg.CURRENT_LIMIT, 1194)[1] & ERR_MASK == \
        ErrorCode.DATA_RANGE
    assert ph.write2ByteTxRx(port, xm, Reg.CURRENT_LIMIT, 1193) == (COMM_SUCCESS, 0)
    xc430 = _id("XC430-W150")
    assert ph.write2ByteTxRx(port, xc430, Reg.CURRENT_LIMIT, 100)[1] & ERR_MASK == \
        ErrorCode.ACCESS
    assert ph.write1ByteTxRx(port, xc430, Reg.OPERATING_MODE, 5)[1] & ERR_MASK == \
        ErrorCode.DATA_RANGE  # no current-based position mode on an XC430


def test_defaults_after_a_reboot_follow_the_model(
    line: tuple[SimBus, PortHandler, PacketHandler],
) -> None:
    _, port, ph = line
    for name, m in MODELS.items():
        i = _id(name)
        assert ph.ping(port, i)[0] == m.model_number
        assert ph.read4ByteTxRx(port, i, Reg.VELOCITY_LIMIT)[0] == m.defaults[Reg.VELOCITY_LIMIT]
        assert ph.read2ByteTxRx(port, i, Reg.POSITION_P_GAIN)[0] == m.position_p_gain
        assert ph.read2ByteTxRx(port, i, Reg.PRESENT_INPUT_VOLTAGE)[0] == m.nominal_voltage_dv
        if m.has_current:
            # Goal Current starts at Current Limit, also after a reboot
            assert ph.write2ByteTxRx(port, i, Reg.GOAL_CURRENT, 5) == (COMM_SUCCESS, 0)
            assert ph.reboot(port, i)[0] == COMM_SUCCESS
            time.sleep(0.15)
            assert ph.read2ByteTxRx(port, i, Reg.GOAL_CURRENT)[0] == m.current_limit


def test_moving_status_in_position_and_present_pwm(
    line: tuple[SimBus, PortHandler, PacketHandler],
) -> None:
    bus, port, ph = line
    i = _id("XL330-M288")
    assert ph.write1ByteTxRx(port, i, Reg.TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0)
    start = ph.read4ByteTxRx(port, i, Reg.PRESENT_POSITION)[0]
    goal = start + 1500
    assert ph.write4ByteTxRx(port, i, Reg.GOAL_POSITION, goal) == (COMM_SUCCESS, 0)
    moving_seen = 0
    pwm_seen = 0
    reached_at = None
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:
        status = ph.read1ByteTxRx(port, i, Reg.MOVING_STATUS)[0]
        present = ph.read4ByteTxRx(port, i, Reg.PRESENT_POSITION)[0]
        now = time.monotonic()
        threshold = MODELS["XL330-M288"].defaults[Reg.MOVING_THRESHOLD]
        if abs(goal - present) > threshold:
            assert not status & 0x01, (present, goal)  # clear while it moves
            moving_seen += 1
            pwm = ph.read2ByteTxRx(port, i, Reg.PRESENT_PWM)[0]
            pwm_seen = max(pwm_seen, pwm if pwm < 0x8000 else pwm - 0x10000)
        elif reached_at is None:
            reached_at = now
        if status & 0x01:
            assert reached_at is not None and now - reached_at <= 0.05
            break
        time.sleep(0.002)
    else:
        pytest.fail("In-Position never set")
    assert moving_seen > 5
    assert 0 < pwm_seen <= 885  # a moving motor draws PWM, at most PWM Limit
    # at rest, without load, the motor needs no PWM (the bus thread may lag on a busy host)
    deadline = time.monotonic() + 0.5
    while ph.read2ByteTxRx(port, i, Reg.PRESENT_PWM)[0] and time.monotonic() < deadline:
        time.sleep(0.01)
    assert ph.read2ByteTxRx(port, i, Reg.PRESENT_PWM)[0] == 0
    assert bus.servo(i).present == goal


def test_profile_velocity_drives_the_trajectory_registers(
    line: tuple[SimBus, PortHandler, PacketHandler],
) -> None:
    _, port, ph = line
    i = _id("XC330-M288")
    assert ph.write4ByteTxRx(port, i, Reg.PROFILE_VELOCITY, 100) == (COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, i, Reg.PROFILE_ACCELERATION, 50) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, i, Reg.TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0)
    start = ph.read4ByteTxRx(port, i, Reg.PRESENT_POSITION)[0]
    goal = start + 2000
    assert ph.write4ByteTxRx(port, i, Reg.GOAL_POSITION, goal) == (COMM_SUCCESS, 0)
    time.sleep(0.15)
    status = ph.read1ByteTxRx(port, i, Reg.MOVING_STATUS)[0]
    assert status & 0x02 and status & 0x30 == 0x30  # ongoing, trapezoidal
    vel = ph.read4ByteTxRx(port, i, Reg.VELOCITY_TRAJECTORY)[0]
    traj = ph.read4ByteTxRx(port, i, Reg.POSITION_TRAJECTORY)[0]
    assert 0 < vel <= 100
    assert start < traj < goal
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        status = ph.read1ByteTxRx(port, i, Reg.MOVING_STATUS)[0]
        if status & 0x01:
            break
        time.sleep(0.01)
    assert status & 0x03 == 0x01  # done: In-Position, no longer ongoing
    assert ph.read4ByteTxRx(port, i, Reg.POSITION_TRAJECTORY)[0] == goal
    assert ph.read4ByteTxRx(port, i, Reg.VELOCITY_TRAJECTORY)[0] == 0


def test_profile_type_triangular_and_rectangular() -> None:
    s = EmulatedServo(1, "XL330-M288")
    s.write(Reg.PROFILE_VELOCITY, (200).to_bytes(4, "little"))
    s.write(Reg.PROFILE_ACCELERATION, (10).to_bytes(4, "little"))
    s.write(Reg.TORQUE_ENABLE, b"\x01")
    s.write(Reg.GOAL_POSITION, (2048 + 50).to_bytes(4, "little"))  # too short for 200
    s.advance(0.002)
    assert s.get(Reg.MOVING_STATUS) & 0x30 == 0x20
    s.write(Reg.PROFILE_ACCELERATION, bytes(4))
    s.write(Reg.GOAL_POSITION, (2048 - 500).to_bytes(4, "little"))
    s.advance(0.002)
    assert s.get(Reg.MOVING_STATUS) & 0x30 == 0x10


def test_input_voltage_error_follows_shutdown() -> None:
    xl = EmulatedServo(1, "XL330-M288")  # Shutdown 53: input voltage stops the motor
    xc = EmulatedServo(2, "XC330-M288")  # Shutdown 52: it does not
    for s in (xl, xc):
        s.write(Reg.TORQUE_ENABLE, b"\x01")
        s.set_supply_voltage(5.0)
        assert s.hardware_error == 0 and s.get(Reg.PRESENT_INPUT_VOLTAGE) == 50
        s.set_supply_voltage(8.0)  # above Max Voltage Limit 7.0 V
        assert s.hardware_error == HardwareError.INPUT_VOLTAGE
        assert s.error_byte() & 0x80
    assert not xl.torque_enabled and xc.torque_enabled
