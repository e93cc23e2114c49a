"""The servo driver on a real bus: skipped unless HANDRIG_PORT names the adapter.

    HANDRIG_PORT=/dev/ttyUSB0 .venv/bin/pytest -m hardware tests/handrig/test_servo_hardware.py

Uses config/rig.toml (IDs, models, baud). The servos are held where they are:
the goals sent are their present positions, clamped to the limits.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from handrig.config.rig import load_rig_config
from handrig.devices.servo import DynamixelBus

PORT = os.environ.get("HANDRIG_PORT", "")

pytestmark = [
    pytest.mark.hardware,
    pytest.mark.skipif(not PORT, reason="HANDRIG_PORT not set (no servo adapter given)"),
]


def test_real_bus_commission_hold_and_release() -> None:
    rig = load_rig_config()
    bus = DynamixelBus(PORT, rig)
    bus.connect()
    try:
        print("\n".join(bus.commissioning))
        state = bus.read_state()
        assert state.all_fresh, state.stale
        with bus.torque(handle_signals=False):
            for _ in range(50):
                bus.write_goals_deg(state.positions_deg)
                now = bus.read_state()
            assert now.all_fresh
            assert np.all(now.hardware_errors == 0)
        assert not bus.torque_enabled
    finally:
        bus.close()
