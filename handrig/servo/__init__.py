"""The servo bus: an abstract :class:`ServoBus` and the Dynamixel adapter on dynamixel-sdk.

This package is the one adapter that imports ``dynamixel_sdk`` and ``serial``;
pipeline code talks to :class:`ServoBus` only.

    from handrig.servo import DynamixelBus
    bus = DynamixelBus("/dev/ttyUSB0", load_rig_config())
    bus.connect()
    with bus.torque():
        bus.write_goals_deg(goals_deg)  # (n,) joint degrees, rig order
        state = bus.read_state()        # ServoState, stale readings marked
    bus.close()
"""

from handrig.servo.bus import BusStats, FaultPolicy, ServoBus, ServoState
from handrig.servo.dynamixel import DynamixelBus, cycle_bytes, wire_time_s

__all__ = [
    "BusStats",
    "DynamixelBus",
    "FaultPolicy",
    "ServoBus",
    "ServoState",
    "cycle_bytes",
    "wire_time_s",
]
