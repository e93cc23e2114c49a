"""Commissioning on an emulated bus is patient; the realtime loop's reads are not.

An emulator shares the host's CPUs: on a busy machine its replies come late, not
never. Torque-on reads every servo's present position first; on an emulated bus
(``DynamixelBus(emulated=True)``, what the factory passes when it started the
emulator) those reads wait until their deadline, so a late emulator does not stop
the rig from starting. (A real bus's reads keep their strict reply deadline; a test
of that with late replies is not reliable: a reply late for one attempt can answer
the next.)
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from collections.abc import Iterator

import pytest

from handrig.config.rig import RigConfig, load_rig_config
from handrig.devices.servo import DynamixelBus
from sim.dxl_bus import FaultSpec, SimBus

# every reply this much late: far past a strict read's deadline (twice the replies'
# wire time plus 2 ms), well inside a command's (COMMAND_TIMEOUT_S, 50 ms)
LATE = FaultSpec(delay=1.0, delay_s=0.008, seed=1)


def _rig(n: int = 4) -> RigConfig:
    rig = load_rig_config()
    return dataclasses.replace(rig, servos=rig.servos[:n])


@pytest.fixture
def late_sim() -> Iterator[SimBus]:
    with SimBus.from_rig(_rig(), wire_timing=True, faults=LATE) as bus:
        yield bus


def test_torque_on_waits_for_a_late_emulator_and_goes_off(late_sim: SimBus) -> None:
    bus = DynamixelBus(late_sim.port_path, _rig(), baud=1_000_000, emulated=True)
    bus.connect()
    try:
        with bus.torque(handle_signals=False):
            assert all(s.torque_enabled for s in late_sim.servos)
    finally:
        bus.close()
    assert not any(s.torque_enabled for s in late_sim.servos)


def test_the_simulated_rig_starts_with_a_core_kept_busy() -> None:
    """The whole simulated rig (emulator on a pty with its puppet, driver, torque on and
    off) beside a process that spins on one core."""
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        rig = _rig(20)
        with SimBus.from_rig(rig, wire_timing=True, puppet=True) as sim:
            bus = DynamixelBus(sim.port_path, rig, baud=rig.bus.baud, emulated=True)
            bus.connect()
            try:
                with bus.torque(handle_signals=False):
                    assert all(s.torque_enabled for s in sim.servos)
                    bus.write_goals_deg(bus.last_goals_deg)
            finally:
                bus.close()
            assert not any(s.torque_enabled for s in sim.servos)
    finally:
        busy.kill()
        busy.wait()
