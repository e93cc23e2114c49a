"""SIGKILL cannot be caught: what stops the servos then is their Bus Watchdog.

A real ``handrig run`` drives emulated servos that this test holds (a SimBus on a
pty in this process, so they outlive the rig); the rig is SIGKILLed mid-run and
every servo's watchdog must trip within ``rig.bus.watchdog_ms`` of the last
bytes it heard, stop where it is and refuse goals until the watchdog is cleared.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np

from firmware_protocol import dynamixel as dx
from handrig.config.rig import load_rig_config
from handrig.devices.servo.positions import deg_to_ticks
from sim.demo_recording import DEMO_RECORDING
from sim.dxl_bus import SimBus

CLI = [sys.executable, "-m", "handrig.cli"]
BUS_WATCHDOG = 98
TRIPPED = 0xFF
# The emulator checks its watchdogs between packets and while the line is idle; on a
# loaded machine its thread can be late by a scheduler slice or two.
CHECK_SLACK_S = 0.06


def test_sigkill_mid_run_the_bus_watchdog_stops_every_servo_within_its_time() -> None:
    rig = load_rig_config()
    watchdog_s = rig.bus.watchdog_ms / 1000.0
    assert watchdog_s > 0, "the shipped rig arms the Bus Watchdog"
    with SimBus.from_rig(rig) as sim:
        proc = subprocess.Popen(
            [*CLI, "run", "--glove", f"replay:{DEMO_RECORDING}", "--bus", sim.port_path,
             "--seconds", "60"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        try:
            servos = [sim.servo(s.id) for s in rig.servos]
            deadline = time.monotonic() + 60
            armed = rig.bus.watchdog_ms // 20
            while time.monotonic() < deadline and not all(
                    s.torque_enabled and s.mem[BUS_WATCHDOG] == armed for s in servos):
                time.sleep(0.01)
            assert all(s.torque_enabled for s in servos), "the rig never turned torque on"
            time.sleep(0.5)  # mid-run: goals flowing
            goals_before = sim.stats.goals_decoded
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
            assert sim.stats.goals_decoded > goals_before or goals_before > 0
            tripped_at: dict[int, float] = {}
            until = time.monotonic() + 5 * watchdog_s + 1.0
            while len(tripped_at) < len(servos) and time.monotonic() < until:
                now = sim.clock.now()
                for s in servos:
                    if s.id not in tripped_at and s.mem[BUS_WATCHDOG] == TRIPPED:
                        tripped_at[s.id] = now - s.last_heard
                time.sleep(0.002)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        assert len(tripped_at) == len(servos), (
            f"watchdog tripped on {sorted(tripped_at)} only")
        worst = max(tripped_at.values())
        assert worst <= watchdog_s + CHECK_SLACK_S, (
            f"a watchdog tripped {worst * 1e3:.0f} ms after the last bytes "
            f"(Bus Watchdog {rig.bus.watchdog_ms} ms)")
        # stopped where it is: the goal is the present position
        for s in servos:
            assert s.goal == s.present or abs(s.goal - s.present) <= 1
        # and goals are refused until the watchdog is cleared with 0
        s = servos[0]
        held = s.goal
        cal = rig.servos[0]
        away = deg_to_ticks(cal, cal.max_deg if held < deg_to_ticks(cal, 0.0) else cal.min_deg)
        packet = dx.build_instruction(
            dx.BROADCAST_ID, dx.Instruction.SYNC_WRITE,
            dx.sync_write_params(dx.Reg.GOAL_POSITION, 4, [(s.id, away.to_bytes(4, "little",
                                                                              signed=True))]))
        fd = os.open(sim.port_path, os.O_RDWR | os.O_NOCTTY)
        try:
            os.write(fd, packet)
            time.sleep(0.1)
        finally:
            os.close(fd)
        assert s.mem[BUS_WATCHDOG] == TRIPPED
        assert s.goal == held and not np.isclose(held, away)
