"""Acceptance: a plain dynamixel-sdk client (no handrig code) against ``handrig sim-bus``
run as a subprocess; the MuJoCo puppet's joints move to the goals sent."""

from __future__ import annotations

import signal
import subprocess
import time

import pytest
from dynamixel_sdk import (
    COMM_SUCCESS,
    GroupBulkRead,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)

from handrig.config.rig import load_rig_config
from handrig.devices.servo.models import MODEL_NUMBERS, servo_model
from handrig.devices.servo.positions import deg_to_ticks, ticks_to_deg
from tests.helpers.emulator import SimBusProcess, start_sim_bus

ADDR_TORQUE, ADDR_GOAL, ADDR_PRESENT, ADDR_RDT = 64, 116, 132, 9


def _signed32(v: int) -> int:
    return v - (1 << 32) if v >= 1 << 31 else v


@pytest.mark.sim_bus("--wire-timing", stderr=subprocess.PIPE)
def test_plain_sdk_client_drives_the_puppet(sim_bus: SimBusProcess) -> None:
    proc, path = sim_bus.proc, sim_bus.port
    rig = load_rig_config()
    ids = [s.id for s in rig.servos]
    number = {s.id: MODEL_NUMBERS[servo_model(s)] for s in rig.servos}  # XL330s, XM430 wrist
    port = PortHandler(path)
    assert port.openPort() and port.setBaudRate(1_000_000)
    ph = PacketHandler(2.0)
    try:
        for i in ids:
            model, result, error = ph.ping(port, i)
            assert (model, result, error) == (number[i], COMM_SUCCESS, 0), i
        found, result = ph.broadcastPing(port)
        assert result == COMM_SUCCESS and sorted(found) == ids
        assert all(v[0] == number[i] for i, v in found.items())
        assert ph.read2ByteTxRx(port, ids[0], 0) == (1200, COMM_SUCCESS, 0)
        assert ph.read2ByteTxRx(port, ids[-1], 0) == (number[ids[-1]], COMM_SUCCESS, 0)
        fsr = GroupSyncRead(port, ph, ADDR_PRESENT, 4)
        for i in ids:
            fsr.addParam(i)
        assert fsr.fastSyncRead() == COMM_SUCCESS
        start = {i: _signed32(fsr.getData(i, ADDR_PRESENT, 4)) for i in ids}
        for i in ids:
            assert ph.write1ByteTxRx(port, i, ADDR_RDT, 0) == (COMM_SUCCESS, 0)
            assert ph.write1ByteTxRx(port, i, ADDR_TORQUE, 1) == (COMM_SUCCESS, 0)
        # goals: three quarters of the way into each servo's range
        goals = {s.id: deg_to_ticks(s, s.min_deg + 0.75 * (s.max_deg - s.min_deg))
                 for s in rig.servos}
        sw = GroupSyncWrite(port, ph, ADDR_GOAL, 4)
        for i, g in goals.items():
            assert sw.addParam(i, g.to_bytes(4, "little", signed=True))
        assert sw.txPacket() == COMM_SUCCESS
        # the wrist carries the whole hand on one XL330 and droops (P-only servo);
        # every finger joint settles within 2 deg of its goal
        tol = {s.id: 12.0 if "Wrist" in s.joint else 2.0 for s in rig.servos}

        def there(present: dict[int, int]) -> bool:
            return all(abs(ticks_to_deg(s, present[s.id]) - ticks_to_deg(s, goals[s.id]))
                       < tol[s.id] for s in rig.servos)

        # until every joint is there (a few tenths of a second at the servos' speed
        # limit), then 0.1 s more to settle; at most 5 s
        deadline = time.monotonic() + 5.0
        while True:
            assert fsr.fastSyncRead() == COMM_SUCCESS
            fast = {i: _signed32(fsr.getData(i, ADDR_PRESENT, 4)) for i in ids}
            if there(fast) or time.monotonic() > deadline:
                break
            time.sleep(0.02)
        time.sleep(0.1)
        assert fsr.fastSyncRead() == COMM_SUCCESS
        fast = {i: _signed32(fsr.getData(i, ADDR_PRESENT, 4)) for i in ids}
        assert fsr.txRxPacket() == COMM_SUCCESS
        plain = {i: _signed32(fsr.getData(i, ADDR_PRESENT, 4)) for i in ids}
        br = GroupBulkRead(port, ph)
        for i in ids:
            assert br.addParam(i, ADDR_PRESENT, 4)
        assert br.txRxPacket() == COMM_SUCCESS
        bulk = {i: _signed32(br.getData(i, ADDR_PRESENT, 4)) for i in ids}

        for s in rig.servos:
            want_deg = ticks_to_deg(s, goals[s.id])
            got_deg = ticks_to_deg(s, fast[s.id])
            assert abs(got_deg - want_deg) < tol[s.id], (s.joint, want_deg, got_deg)
            # the joint moved there: it started at least 5 deg away
            assert abs(ticks_to_deg(s, start[s.id]) - want_deg) > 5.0, s.joint
            for other in (plain, bulk):
                assert abs(other[s.id] - fast[s.id]) <= 20  # read a few ms apart, still settling
    finally:
        port.closePort()

    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    assert "packets" in out


def test_faults_viewer_without_display_and_summary() -> None:
    import os

    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    with start_sim_bus("--ids", "1-3", "--no-puppet", "--faults", "missing=2,drop=1,seed=1",
                       "--viewer", "--no-realtime", stderr=subprocess.PIPE, env=env) as bus:
        proc = bus.proc
        port = PortHandler(bus.port)
        assert port.openPort()
        ph = PacketHandler(2.0)
        for i in (1, 2, 3):
            assert ph.ping(port, i)[1] != COMM_SUCCESS
        port.closePort()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    assert "viewer: unavailable (no display" in err
    assert "dropped 2" in out and "missing 1" in out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--ids", "1-x"], "--ids"),
        (["--ids", "300"], "out of range"),
        (["--servos", "0"], "servo count"),
        (["--model", "AX-12"], "unknown servo model"),
        (["--faults", "explode=1"], "unknown fault"),
        (["--faults", "drop=2"], "out of range"),
    ],
)
def test_bad_arguments_one_line_exit_2(
    args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from handrig.cli import main

    assert main(["sim-bus", *args]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
