"""A rebooted servo gets back the rig's Return Delay Time, as commissioning set it: the
driver's reboot used to write 0 whatever the rig said ([servo_settings] return_delay_us),
and the reply timing the driver counts on (its held-reply rule among them) with it."""

from __future__ import annotations

import dataclasses

from firmware_protocol import dynamixel as dx
from tests.helpers.servos import make_bus, small_rig

RETURN_DELAY_ADDRESS = 9  # Return Delay Time (X-series control table, 2 us a unit)


def test_a_rebooted_servo_keeps_the_rigs_return_delay_time() -> None:
    rig = small_rig()
    rig = dataclasses.replace(rig, servo_settings=dataclasses.replace(
        rig.servo_settings, return_delay_us=100))
    bus, _, peer = make_bus(rig)
    servo = peer.servo(5)
    assert servo.mem[RETURN_DELAY_ADDRESS] == 50  # commissioned: 100 us
    with bus.torque(handle_signals=False):
        servo.inject_hardware_error(dx.HardwareError.OVERLOAD)
        bus.read_state(bus.clock.now() + 0.5)
        assert bus.stats.reboots[4] == 1 and servo.counters["reboots"] == 1
        assert servo.mem[RETURN_DELAY_ADDRESS] == 50
