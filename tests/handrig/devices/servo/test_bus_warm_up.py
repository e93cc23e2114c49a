"""The bus's warm-up (handrig/devices/servo/fast_read.py): while a read's reply is on the
wire the driver decodes the last whole reply again and builds its last goals into a
scratch Sync Write. Through the byte-level emulator on a fake clock, a bus with the
warm-up and one without send the same bytes and return the same states and counters;
the warm-up's rehearsals are counted."""

from __future__ import annotations

import numpy as np

from handrig.clock import FakeClock
from handrig.config.rig import load_rig_config
from handrig.config.rig_files import SHIPPED_RIG
from handrig.devices.servo import DynamixelBus, ServoState
from tests.handrig.devices.servo.servo_fakes import EmulatorTransport, PeerBus

BAUD = 4_000_000
CYCLES = 30


def _run(warm_up: bool) -> tuple[DynamixelBus, EmulatorTransport, list[ServoState]]:
    rig = load_rig_config(SHIPPED_RIG)
    clock = FakeClock(100.0)
    transport = EmulatorTransport(PeerBus(rig), clock, BAUD)
    bus = DynamixelBus("fake:emulator", rig, baud=BAUD, clock=clock, transport=transport,
                       read_fields="position", warm_up=warm_up)
    bus.connect()
    lo = np.array([s.min_deg for s in rig.servos])
    hi = np.array([s.max_deg for s in rig.servos])
    states = []
    for k in range(CYCLES):
        goals = lo + (hi - lo) * (0.5 + 0.4 * np.sin(0.3 * k))
        goals[k % len(goals)] = np.nan  # held at the last goal sent
        bus.write_goals_deg(goals)
        states.append(bus.read_state())
    bus.close()
    return bus, transport, states


def test_the_warm_up_changes_no_byte_no_state_and_no_counter() -> None:
    warm, warm_port, warm_states = _run(True)
    cold, cold_port, cold_states = _run(False)
    assert warm_port.writes == cold_port.writes  # the rehearsal sends nothing
    for a, b in zip(warm_states, cold_states, strict=True):
        assert not a.stale.any()
        np.testing.assert_array_equal(a.positions_deg, b.positions_deg)
        np.testing.assert_array_equal(a.stale, b.stale)
        assert a.timestamp_s == b.timestamp_s
    assert warm.stats.summary() == cold.stats.summary()
    np.testing.assert_array_equal(warm.last_goals_deg, cold.last_goals_deg)
    # a rehearsal in each whole read after the first reply (commissioning's reads too)
    assert warm.fast.rehearsals >= CYCLES - 1
    assert cold.fast.rehearsals == 0
