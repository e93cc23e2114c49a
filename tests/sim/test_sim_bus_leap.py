"""``handrig sim-bus --rig leap`` serves the LEAP puppet to a plain dynamixel-sdk client at
4 Mbps: 16 XC330-M288s (model 1240), IDs 0-15, and a goal moves the model's joint."""

from __future__ import annotations

import subprocess
import time

import pytest
from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

from tests.helpers.emulator import SimBusProcess

pytest.importorskip("mujoco")
ADDR_TORQUE, ADDR_GOAL, ADDR_PRESENT = 64, 116, 132


@pytest.mark.sim_bus("--rig", "leap", "--no-realtime", stderr=subprocess.PIPE)
def test_sim_bus_serves_the_leap_hand(sim_bus: SimBusProcess) -> None:
    proc = sim_bus.proc
    assert proc.stdout is not None
    second = proc.stdout.readline()
    assert "servos: 16 (XC330-M288)" in second and "puppet drives 16" in second
    port = PortHandler(sim_bus.port)
    try:
        assert port.openPort() and port.setBaudRate(4_000_000)
        ph = PacketHandler(2.0)
        for sid in range(16):
            # up to three pings: the emulator's first reply is a cold start, slower than
            # the SDK's timeout at 4 Mbps
            for _ in range(3):
                model, result, _ = ph.ping(port, sid)
                if result == COMM_SUCCESS:
                    break
            assert result == COMM_SUCCESS and model == 1240, sid
        # servo 1 drives if_mcp: 2048 ticks is the model's zero, +512 is 45 deg of flexion
        assert ph.write1ByteTxRx(port, 1, ADDR_TORQUE, 1)[0] == COMM_SUCCESS
        assert ph.write4ByteTxRx(port, 1, ADDR_GOAL, 2048 + 512)[0] == COMM_SUCCESS
        deadline = time.monotonic() + 5.0
        present = 0
        while time.monotonic() < deadline:
            present, result, _ = ph.read4ByteTxRx(port, 1, ADDR_PRESENT)
            if result == COMM_SUCCESS and abs(present - 2560) < 40:
                break
            time.sleep(0.05)
        assert abs(present - 2560) < 40, present
        ph.write1ByteTxRx(port, 1, ADDR_TORQUE, 0)
    finally:
        port.closePort()
