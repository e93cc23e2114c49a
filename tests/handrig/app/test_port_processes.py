"""Emulators started ahead of the step that uses them (handrig.app.port_processes).

Real ``handrig sim-bus`` processes: the bus a run opens on ``sim`` is the one started
for its arguments (no second emulator), one started for other arguments is left to be
stopped, and every one ends by the time its owner is done.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from handrig.app import factory as app
from handrig.app import parts as app_parts
from handrig.app.port_processes import (
    SIM_BUS,
    PortProcess,
    StartedEmulators,
    sim_bus_argv,
)
from handrig.clock import MonotonicClock
from handrig.errors import DeviceError

ROOT = Path(__file__).resolve().parents[3]
RIG = ROOT / "config" / "rig.toml"


def test_servo_bus_takes_the_emulator_started_for_it() -> None:
    parts = app_parts.build_parts(RIG)
    argv = sim_bus_argv(parts.rig_file, parts.hand, wire_timing=False)
    with StartedEmulators() as started:
        other = started.start(sim_bus_argv(parts.rig_file, "ri", wire_timing=False), SIM_BUS)
        mine = started.start(argv, SIM_BUS)
        assert started.start(argv, SIM_BUS) is mine  # started once per argv
        with app.servo_bus("sim", parts, MonotonicClock(), wire_timing=False,
                           log=lambda _: None, started=started) as opened:
            assert opened.emulator is mine.proc
            assert opened.port == mine.port()
            opened.bus.connect()
            assert len(opened.bus.models) == len(parts.rig_config.servos)
        assert mine.proc.poll() is not None  # stopped with the bus it served
        assert started.take(argv) is None  # taken once
        assert other.proc.poll() is None  # not taken: still up until the stack ends
    assert other.proc.poll() is not None


def test_a_process_that_prints_no_port_is_a_device_error_naming_it() -> None:
    with (PortProcess(["sim-bus", "--rig", str(RIG), "--servos", "0"],
                      "the simulated servo bus") as started,
          pytest.raises(DeviceError, match=r"the simulated servo bus did not start .*"
                        r"servo count out of range")):
        started.port(timeout_s=30)
    assert started.proc.poll() is not None
