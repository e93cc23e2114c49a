"""A pseudo-terminal is served by a program: bring-up and commissioning wait for it.

Whoever runs ``handrig servos check --port /dev/pts/N`` or ``handrig run --port
/dev/pts/N`` against an emulator they started themselves did not tell the driver
it is emulated, but a pty cannot be a UART: a program answers there, on the
host's CPUs, and on a loaded machine its replies come late, not never. CI saw
``servos check`` give up on a servo whose three reads went unanswered within the
SDK's 34 ms. Here every reply is later than three such tries.
"""

from __future__ import annotations

import dataclasses
import os

from handrig.config.rig import RigConfig, load_rig_config
from handrig.devices.servo import DynamixelBus
from handrig.devices.servo.dynamixel_bringup import PTY_PATIENCE_MS, scan
from handrig.devices.servo.transport import is_pseudo_terminal
from sim.dxl_bus import FaultSpec, SimBus
from sim.dxl_servo import EmulatedServo

# past three tries of the SDK's own reply timeout (2 x 16 ms latency timer + 2 ms: a
# reply late for one try can answer the next), inside the patience
LATE_S = 0.15
assert LATE_S * 1000 < PTY_PATIENCE_MS


def test_a_pty_is_told_from_other_files() -> None:
    master, slave = os.openpty()
    try:
        assert is_pseudo_terminal(slave)
    finally:
        os.close(master)
        os.close(slave)
    with open(os.devnull, "rb") as f:
        assert not is_pseudo_terminal(f.fileno())


def test_scan_describes_a_servo_whose_replies_come_late() -> None:
    late = FaultSpec(delay=1.0, delay_s=LATE_S, seed=1)
    with SimBus([EmulatedServo(3)], faults=late, realtime=False) as sim:
        found = scan(sim.port_path, [1_000_000])
    assert [s.id for s in found.servos] == [3]
    servo = found.servos[0]
    assert servo.unread == ()
    assert servo.operating_mode == 3 and servo.voltage_v is not None


def _rig(n: int) -> RigConfig:
    rig = load_rig_config()
    return dataclasses.replace(rig, servos=rig.servos[:n])


def test_a_bus_on_a_pty_waits_for_its_servos_at_torque_on() -> None:
    """No ``emulated=True``: the driver sees the pty itself."""
    rig = _rig(4)
    late = FaultSpec(delay=1.0, delay_s=0.008, seed=1)  # past a strict read's deadline
    with SimBus.from_rig(rig, wire_timing=True, faults=late) as sim:
        bus = DynamixelBus(sim.port_path, rig, baud=1_000_000)
        bus.connect()
        try:
            assert bus.transport.pty
            with bus.torque(handle_signals=False):
                assert all(s.torque_enabled for s in sim.servos)
        finally:
            bus.close()
        assert not any(s.torque_enabled for s in sim.servos)
