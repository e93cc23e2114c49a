"""The servo bus: an abstract :class:`ServoBus` and the Dynamixel adapter on dynamixel-sdk.

This package is the one adapter that imports ``dynamixel_sdk`` and ``serial``;
pipeline code talks to :class:`ServoBus` only. Layers, bottom up: ``transport``
(the Transport ABC; SerialTransport on the SDK's PortHandler, deadlines on the
injected Clock), ``codec`` (Protocol 2.0 packets and the compiled kernels that
build and parse them), ``registers`` (the X-series control table as data),
``bus`` (the ABC, ServoState, BusStats, FaultPolicy), then the parts of
``DynamixelBus``: ``roster``, ``wire``, ``link``, ``goals``, ``readings``,
``fast_read``, ``sync_read``, ``reader``, ``faults``, ``commissioning``,
``torque``; ``dynamixel`` is the facade over them. Beside them, ``zeroing`` (the
``ZeroingBus`` contract ``handrig calibrate servos`` talks to) and ``dynamixel_zeroing``
(its Dynamixel side), ``bringup`` (the ``BusBringup`` contract ``handrig servos`` and
``handrig setup`` talk to) and ``dynamixel_bringup`` (its Dynamixel side).

    from handrig.devices.servo import DynamixelBus
    bus = DynamixelBus("/dev/ttyUSB0", load_rig_config())  # baud from the rig file
    bus.connect()                        # DeviceError says which servo is missing/wrong
    with bus.torque():                   # torque off on every way out, SIGTERM included
        n_clamped = bus.write_goals_deg(goals_deg)  # (n,) joint degrees, rig order
        state = bus.read_state()         # ServoState: positions_deg, stale mask, ...
    bus.close()

Units: joint degrees (flexion positive, radial positive), degrees per second,
milliamperes, degrees Celsius, seconds on the bus clock.
"""

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from handrig.devices.servo.bus import BusStats, FaultPolicy, ServoBus, ServoState
    from handrig.devices.servo.dynamixel import DynamixelBus, cycle_bytes, wire_time_s

__all__ = [
    "BusStats",
    "DynamixelBus",
    "FaultPolicy",
    "ServoBus",
    "ServoState",
    "cycle_bytes",
    "wire_time_s",
]
_MODULE_OF = {"BusStats": "bus", "FaultPolicy": "bus", "ServoBus": "bus", "ServoState": "bus",
              "DynamixelBus": "dynamixel", "cycle_bytes": "dynamixel",
              "wire_time_s": "dynamixel"}


def __getattr__(name: str) -> Any:
    """The names above, imported on first use, so that a light module of this package
    (``models``: the model table the bus emulator reads too) comes without the driver
    and its compiled kernels (numba: about 0.3 s at every emulator start)."""
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value
