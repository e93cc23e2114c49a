"""A wedged adapter: the bus emulator stops draining the port (SIGSTOP, as a wedged USB
adapter stops taking bytes). A real ``handrig run`` must end on its own within a
second of the stall, measured from outside (SIGSTOP sent -> the process gone), with a
message naming the port, also when a SIGTERM comes during the stall, and leave the
servos to their Bus Watchdog (tripped once the emulator runs again). The port is a
pty, whose queue cannot be seen: the rig judges it by its answers
(``SerialTransport._judge_drain``), long before the pty's ~19 KB buffer is full.
``python -m bench wedge`` prints the figure over several runs.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

from handrig.config.rig import load_rig_config
from sim.demo_recording import DEMO_RECORDING
from tests.helpers.emulator import SimBusProcess

CLI = [sys.executable, "-m", "handrig.cli"]
BUS_WATCHDOG = 98
TRIPPED = 0xFF
# From the stall to the exit: no answer for ANSWER_STALL_S (0.5 s), the torque-off
# broadcast (nothing can be read back), the summary and the process ending.
EXIT_WITHIN_S = 1.0
pytestmark = pytest.mark.sim_bus("--no-realtime")


def _start_rig(port: str, tmp_path: Path) -> tuple[subprocess.Popen[str], Path]:
    err = tmp_path / "stderr.txt"
    with open(err, "w") as f:
        proc = subprocess.Popen(
            [*CLI, "run", "--glove", f"replay:{DEMO_RECORDING}", "--bus", port,
             "--seconds", "120", "--json"],
            stdout=subprocess.PIPE, stderr=f, text=True, start_new_session=True)
    deadline = time.monotonic() + 120
    while "\nfirst frame" not in err.read_text():  # the loop's first frame
        assert proc.poll() is None, err.read_text()
        assert time.monotonic() < deadline, "the rig's loop never started"
        time.sleep(0.05)
    time.sleep(0.5)  # torque on, past the 0.3 s ease-in: goals flowing
    assert proc.poll() is None, err.read_text()
    return proc, err


def _wait_exit(proc: subprocess.Popen[str], from_s: float) -> float:
    try:
        proc.wait(timeout=EXIT_WITHIN_S + 30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        pytest.fail("handrig run hung on the wedged port")
    return time.monotonic() - from_s


def _summary(proc: subprocess.Popen[str]) -> dict[str, object]:
    assert proc.stdout is not None
    out = proc.stdout.read()
    return dict(json.loads(out.strip().splitlines()[-1]))


def test_a_wedged_adapter_ends_the_run_within_seconds_naming_the_port(
        sim_bus: SimBusProcess, tmp_path: Path) -> None:
    sim, port = sim_bus.proc, sim_bus.port
    rig_proc, _ = _start_rig(port, tmp_path)
    os.kill(sim.pid, signal.SIGSTOP)
    stalled = time.monotonic()
    took = _wait_exit(rig_proc, stalled)
    summary = _summary(rig_proc)
    assert rig_proc.returncode == 1
    assert took <= EXIT_WITHIN_S, f"the run took {took:.2f} s to end after the stall"
    error = str(summary["error"])
    assert port in error and "stopped draining" in error, error
    assert summary["torque_off"] is None  # it could not be confirmed: not claimed
    unconfirmed = "; ".join(summary["torque_off_unconfirmed"])  # each servo named
    rig = load_rig_config()
    assert all(f"servo {s.id} ({s.joint})" in unconfirmed for s in rig.servos), unconfirmed
    # the emulator runs again: every servo's Bus Watchdog has tripped (it heard nothing
    # after the stall), so it stopped where it was
    os.kill(sim.pid, signal.SIGCONT)
    time.sleep(0.5)
    handler = PortHandler(port)
    assert handler.openPort() and handler.setBaudRate(load_rig_config().bus.baud)
    packets = PacketHandler(2.0)
    try:
        for s in load_rig_config().servos:
            value, result, _ = packets.read1ByteTxRx(handler, s.id, BUS_WATCHDOG)
            assert result == COMM_SUCCESS, f"servo {s.id} did not answer"
            assert value == TRIPPED, f"servo {s.id}: Bus Watchdog {value}, not tripped"
    finally:
        handler.closePort()


def test_a_sigterm_during_the_stall_ends_the_run_promptly(
        sim_bus: SimBusProcess, tmp_path: Path) -> None:
    sim, port = sim_bus.proc, sim_bus.port
    rig_proc, err = _start_rig(port, tmp_path)
    os.kill(sim.pid, signal.SIGSTOP)
    stalled = time.monotonic()
    time.sleep(0.2)  # replies lost: the stall not yet judged
    os.kill(rig_proc.pid, signal.SIGTERM)
    took = _wait_exit(rig_proc, stalled)
    summary = _summary(rig_proc)
    os.kill(sim.pid, signal.SIGCONT)
    assert took <= EXIT_WITHIN_S, f"the run took {took:.2f} s to end after the stall"
    assert summary.get("signals") == 1
    said = err.read_text()
    assert "SIGTERM received" in said, said
    # the signal began the ease to the relaxed pose; the stalled port ended it early
    assert rig_proc.returncode == 1 and port in str(summary["error"]), summary
    assert summary["torque_off"] is not True
