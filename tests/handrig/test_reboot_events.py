"""Reboots and hardware errors are events of the run (``--json`` included), said
once: a real ``handrig run`` against the bus emulator on a pty, whose servo 3 reports
an overload once the run follows the glove; and, in process, an overload already there
when the loop starts (found by its first read) is one of the run's events as well.

The overload is injected when the run has said its first frame, not at a time counted
from the emulator's start: on a loaded machine the run's start-up can take longer than
any such time, and an overload the servos already had at commissioning is handled (and
logged) before the run begins."""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
import time
from pathlib import Path

from firmware_protocol.dynamixel import HardwareError
from handrig.app import factory as app
from handrig.app import parts as app_parts
from handrig.clock import MonotonicClock
from handrig.config.rig import load_rig_config
from handrig.devices.glove_recording import read_glove_recording
from sim.demo_recording import DEMO_RECORDING
from sim.dxl_bus import SimBus
from sim.glove_emulator import GloveEmulator

CLI = [sys.executable, "-m", "handrig.cli"]
WHO = "servo 3 (riThumbCMCz)"


def test_a_hardware_error_and_its_reboot_are_events_in_json(tmp_path: Path) -> None:
    rig = load_rig_config()
    with SimBus.from_rig(rig, realtime=False) as sim:
        err = tmp_path / "stderr.txt"
        with open(err, "w") as f:
            proc = subprocess.Popen(
                [*CLI, "run", "--glove", f"replay:{DEMO_RECORDING}", "--bus", sim.port_path,
                 "--seconds", "2", "--json"], stdout=subprocess.PIPE, stderr=f, text=True)
        try:
            deadline = time.monotonic() + 120
            while "first frame" not in err.read_text():  # the loop runs
                assert proc.poll() is None, err.read_text()
                assert time.monotonic() < deadline, "the run never got its first frame"
                time.sleep(0.02)
            with sim.lock:
                sim.servo(3).inject_hardware_error(HardwareError.OVERLOAD)
            out, _ = proc.communicate(timeout=120)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    summary = json.loads(out.strip().splitlines()[-1])
    events = summary["events"]
    assert summary["bus"]["reboots"] == 1, summary["bus"]
    hw = [e for e in events if f"{WHO} hardware error" in e]
    assert len(hw) == 1 and "overload" in hw[0] and "rebooting it" in hw[0], events
    back = [e for e in events if f"{WHO} rebooted" in e]
    assert back, events
    text = err.read_text()
    assert text.count(hw[0]) == 1, text  # said once


def test_an_overload_there_when_the_loop_starts_is_an_event_of_the_run() -> None:
    """Commissioned and torque on, then servo 3 overloads before the loop's first cycle:
    its first read finds it, and it is in the run's events (not in the log alone)."""
    parts = app_parts.build_parts()
    clock = MonotonicClock()
    log: list[str] = []
    rec = read_glove_recording(DEMO_RECORDING)
    with SimBus.from_rig(parts.rig_config, realtime=False) as sim, \
            GloveEmulator(rec, "frames", rate_hz=200.0, loop=True) as emu, \
            contextlib.ExitStack() as stack:
        opened = stack.enter_context(app.servo_bus(sim.port_path, parts, clock,
                                                   log=log.append))
        glove = stack.enter_context(app.open_glove(emu.port_path, parts.glove_config, clock))
        opened.bus.connect()
        rig = app.build_rig(parts, glove, opened.bus, clock, log=log.append)
        rig.prepare()
        with opened.bus.torque(handle_signals=False):
            with sim.lock:
                sim.servo(3).inject_hardware_error(HardwareError.OVERLOAD)
            stats = rig.run(duration_s=0.5)
    events = list(stats.events)
    hw = [e for e in events if f"{WHO} hardware error" in e]
    assert len(hw) == 1 and "rebooting it" in hw[0], (events, log)
    assert any(f"{WHO} rebooted" in e for e in events), events
