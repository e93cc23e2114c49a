"""Baud per servo and the emulator's end of the pty, seen by a plain dynamixel-sdk client.

A servo answers only at its own Baud Rate item (a real one at another rate decodes
noise and stays silent); ``handrig sim-bus --servo-baud`` starts servos at
different rates. The emulator holds only its end of the pty, so a client that
checks the port for other holders (as GELLO's driver does with ``fuser``) finds
none, and a client may close the port and open it again.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

from handrig.errors import ConfigError
from sim.dxl_bus import SimBus
from sim.dxl_servo import EmulatedServo
from tests.helpers.emulator import SimBusProcess

ADDR_BAUD = 8


def _ping_all(path: str, baud: int) -> list[int]:
    port = PortHandler(path)
    assert port.openPort() and port.setBaudRate(baud)
    try:
        found, result = PacketHandler(2.0).broadcastPing(port)
        return sorted(found) if result == COMM_SUCCESS else []
    finally:
        port.closePort()


def test_a_servo_at_57600_is_silent_to_a_client_at_1_mbps() -> None:
    servos = [EmulatedServo(5, baud=57_600), EmulatedServo(9, baud=1_000_000)]
    with SimBus(servos) as bus:
        port = PortHandler(bus.port_path)
        assert port.openPort() and port.setBaudRate(1_000_000)
        ph = PacketHandler(2.0)
        _, result, _ = ph.ping(port, 5)
        assert result != COMM_SUCCESS  # silent: no reply at all
        assert ph.ping(port, 9)[1] == COMM_SUCCESS
        assert port.setBaudRate(57_600)
        assert ph.ping(port, 5) == (1200, COMM_SUCCESS, 0)
        assert ph.ping(port, 9)[1] != COMM_SUCCESS
        # a new Baud Rate takes effect at once: the servo is then heard at 115200 only
        assert ph.write1ByteTxRx(port, 5, ADDR_BAUD, 2) == (COMM_SUCCESS, 0)
        assert ph.ping(port, 5)[1] != COMM_SUCCESS
        assert port.setBaudRate(115_200)
        assert ph.ping(port, 5) == (1200, COMM_SUCCESS, 0)
        assert bus.servo(5).baud == 115_200
        port.closePort()


def test_an_unknown_baud_is_refused() -> None:
    with pytest.raises(ValueError, match="250000 baud is not an X-series rate"):
        EmulatedServo(1, baud=250_000)


@pytest.mark.sim_bus("--no-puppet", "--ids", "1,2,3,40",
                     "--servo-baud", "1:57600,2:115200,3:1000000,40:57600",
                     stderr=subprocess.PIPE)
def test_sim_bus_servo_baud_flag(sim_bus: SimBusProcess) -> None:
    proc, path = sim_bus.proc, sim_bus.port
    assert proc.stdout is not None
    assert "baud 57600, 115200, 1000000" in proc.stdout.readline()  # the "servos:" line
    assert _ping_all(path, 57_600) == [1, 40]
    assert _ping_all(path, 115_200) == [2]
    assert _ping_all(path, 1_000_000) == [3]
    assert _ping_all(path, 2_000_000) == []
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=10)
    assert proc.returncode == 0
    assert "sim-bus: " in out and "0 bad CRC" in out


@pytest.mark.parametrize("spec, message", [
    ("1:250000", "not a Dynamixel X baud rate"),
    ("7:57600", "no servo with this ID on the bus"),
    ("1-57600", "not ID:BAUD"),
    ("1:57600,1:115200", "servo ID given twice"),
])
def test_sim_bus_servo_baud_bad_input(spec: str, message: str) -> None:
    from handrig.cli.sim_bus import parse_servo_bauds

    with pytest.raises(ConfigError, match=message):
        parse_servo_bauds(spec, [1, 2, 3])


def _holders(path: str) -> list[int]:
    """PIDs with ``path`` open (what ``fuser`` reports), from /proc."""
    target = os.stat(path).st_rdev
    out = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        fd_dir = Path("/proc", pid, "fd")
        try:
            fds = list(fd_dir.iterdir())
        except OSError:
            continue
        for fd in fds:
            try:
                st = os.stat(fd)
            except OSError:
                continue
            if st.st_rdev == target and (st.st_mode & 0o170000) == 0o020000:
                out.append(int(pid))
                break
    return out


def test_the_emulator_holds_no_end_a_client_opens() -> None:
    with SimBus([EmulatedServo(1)]) as bus:
        assert _holders(bus.port_path) == []  # a port-busy check finds it free
        assert not bus.client_open
        port = PortHandler(bus.port_path)
        assert port.openPort() and port.setBaudRate(1_000_000)
        assert _holders(bus.port_path) == [os.getpid()]  # only the client
        port.closePort()


def test_a_client_that_probes_closes_and_reopens_is_served() -> None:
    with SimBus([EmulatedServo(1), EmulatedServo(2)]) as bus:
        ph = PacketHandler(2.0)
        # GELLO-style probe: open, close, open again, then work
        for _ in range(3):
            fd = os.open(bus.port_path, os.O_RDWR | os.O_NOCTTY)
            os.close(fd)
        sessions = []
        for _ in range(3):
            port = PortHandler(bus.port_path)
            assert port.openPort() and port.setBaudRate(1_000_000)
            assert ph.ping(port, 2) == (1200, COMM_SUCCESS, 0)
            # half a packet left on the line when the client goes: noise, not a frame
            port.writePort(bytes.fromhex("ff ff fd 00 01 07"))
            sessions.append(bus.client_sessions)
            port.closePort()
            deadline = time.monotonic() + 1.0
            while bus.client_open and time.monotonic() < deadline:
                time.sleep(0.005)
            assert not bus.client_open
        assert bus.running and bus.error is None
        time.sleep(0.05)  # the bus thread counts the last half packet as noise
        assert sessions == sorted(set(sessions)) and len(sessions) == 3  # each noticed
        assert bus.client_closes == 3
        assert bus.stats.noise_bytes >= 3 * 6
