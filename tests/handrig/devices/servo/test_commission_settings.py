"""Commissioning writes and reads back a rig file's [servo_settings], per servo, through the
byte-level emulator (fake transport, fake clock): the LEAP preset at 4 Mbps, a servo
that keeps another value, settings left unset, and the human rig as before."""

from __future__ import annotations

import dataclasses

import pytest

from firmware_protocol import dynamixel as dx
from handrig.clock import FakeClock
from handrig.config.rig import RigConfig, ServoSettings, load_rig_config
from handrig.devices.servo import DynamixelBus
from handrig.devices.servo.commissioning import servo_settings
from handrig.devices.servo.models import servo_settings_for
from handrig.errors import DeviceError
from handrig.pose.robot_rig import RobotRigConfig, load_rig
from sim.dxl_servo import EmulatedServo
from tests.handrig.devices.servo.servo_fakes import EmulatorTransport, PeerBus

BAUD = 4_000_000


def _leap() -> RobotRigConfig:
    rig = load_rig("leap")
    assert isinstance(rig, RobotRigConfig)
    return rig


def _bus(rig: RigConfig, peer: PeerBus | None = None) -> tuple[DynamixelBus, EmulatorTransport,
                                                                PeerBus]:
    clock = FakeClock(100.0)
    peer = peer or PeerBus(rig)
    transport = EmulatorTransport(peer, clock, BAUD)
    bus = DynamixelBus("fake:emulator", rig, baud=BAUD, clock=clock, transport=transport)
    return bus, transport, peer


def test_leap_commissioning_sets_every_servo_setting() -> None:
    rig = _leap()
    bus, _, peer = _bus(rig)
    bus.connect()
    for s in rig.servos:
        servo, want = peer.servo(s.id), servo_settings_for(rig, s.id)
        side = s.id in (0, 4, 8)
        assert servo.get(dx.Reg.OPERATING_MODE) == 5
        assert servo.get(dx.Reg.RETURN_DELAY_TIME) == 0
        assert servo.get(dx.Reg.CURRENT_LIMIT) == 350 == want.current_limit_ma
        assert servo.get(dx.Reg.GOAL_CURRENT) == 350
        assert servo.get(dx.Reg.POSITION_P_GAIN) == (450 if side else 600)
        assert servo.get(dx.Reg.POSITION_D_GAIN) == (150 if side else 200)
        assert servo.get(dx.Reg.TORQUE_ENABLE) == 0
    text = "\n".join(bus.commissioning)
    assert "servo 1 (if_mcp): OPERATING_MODE 3 -> 5 (current-based position control mode)" \
        in text
    assert "servo 0 (if_rot): POSITION_P_GAIN" in text and "-> 450" in text
    assert "current-based position mode" in text and "P/D gains of [servo_settings]" in text
    bus.close()


def test_a_second_connect_finds_everything_set() -> None:
    rig = _leap()
    bus, _, peer = _bus(rig)
    bus.connect()
    bus.close()
    again, transport2, _ = _bus(rig, peer)
    again.connect()
    assert not any("->" in line for line in again.commissioning)
    writes = [dx.parse_instruction(w) for w in transport2.writes]
    eeprom = {int(r) for r in (dx.Reg.OPERATING_MODE, dx.Reg.CURRENT_LIMIT)}
    assert not any(p.instruction == dx.Instruction.WRITE
                   and int.from_bytes(p.params[:2], "little") in eeprom for p in writes)
    again.close()


class _StubbornServo(EmulatedServo):
    """A servo that acknowledges a P gain write and keeps its own value."""

    def write(self, address: int, data: bytes) -> int:
        if address == int(dx.Reg.POSITION_P_GAIN):
            return self.error_byte()
        return super().write(address, data)


def test_a_servo_that_keeps_another_value_is_named() -> None:
    rig = _leap()
    peer = PeerBus(rig)
    old = peer.servo(5)
    stubborn = _StubbornServo(5, "XC330-M288", baud=BAUD)
    stubborn.mem[:] = old.mem
    peer.servos[peer.servos.index(old)] = stubborn
    peer._kinematic = list(peer.servos)
    peer._rebuild_ids()
    bus, _, _ = _bus(rig, peer)
    with pytest.raises(DeviceError) as err:
        bus.connect()
    text = str(err.value)
    default_p = old.info.position_p_gain
    assert "servo 5 (mf_mcp)" in text and "POSITION_P_GAIN" in text
    assert f"reads {default_p} after writing 600" in text
    bus.close()


def test_unset_settings_are_not_written() -> None:
    rig = dataclasses.replace(_leap(), servo_settings=ServoSettings(
        operating_mode="current_based_position", position_d_gain=100))
    regs = [r.name for r, _, _ in servo_settings(rig, 0)]
    assert regs == ["RETURN_DELAY_TIME", "OPERATING_MODE", "POSITION_D_GAIN"]
    bus, _, peer = _bus(rig)
    bus.connect()
    servo = peer.servo(0)
    assert servo.get(dx.Reg.POSITION_D_GAIN) == 100
    assert servo.get(dx.Reg.POSITION_P_GAIN) == servo.info.position_p_gain
    assert servo.get(dx.Reg.CURRENT_LIMIT) == servo.info.current_limit
    bus.close()


def test_the_human_rig_writes_only_what_it_wrote_before() -> None:
    rig = dataclasses.replace(load_rig_config(), servos=load_rig_config().servos[:4])
    assert [(r.name, v) for r, v, _ in servo_settings(rig, 0)] == [
        ("RETURN_DELAY_TIME", 0), ("OPERATING_MODE", 3)]
    clock = FakeClock(100.0)
    peer = PeerBus(rig)
    transport = EmulatorTransport(peer, clock, 1_000_000)
    bus = DynamixelBus("fake:emulator", rig, baud=1_000_000, clock=clock, transport=transport)
    bus.connect()
    written = {int.from_bytes(p.params[:2], "little")
               for p in map(dx.parse_instruction, transport.writes)
               if p.instruction == dx.Instruction.WRITE}
    assert written <= {int(r) for r in (dx.Reg.RETURN_DELAY_TIME, dx.Reg.OPERATING_MODE,
                                        dx.Reg.TORQUE_ENABLE, dx.Reg.BUS_WATCHDOG,
                                        dx.Reg.STATUS_RETURN_LEVEL)}
    assert "return delay 0, position mode, status level 2, watchdog cleared: done" in \
        bus.commissioning
    bus.close()
