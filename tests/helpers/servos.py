"""The servo tests' shared pieces: a rig of the first few shipped servos, their limits in
ticks, what the emulated servos got, and a driver on the in-process emulator."""

from __future__ import annotations

import dataclasses

import numpy as np

from handrig.clock import FakeClock
from handrig.config.rig import RigConfig, load_rig_config
from handrig.devices.servo import DynamixelBus
from handrig.devices.servo.positions import deg_to_ticks
from sim.dxl_bus import FaultSpec, SimBus
from tests.handrig.devices.servo.servo_fakes import EmulatorTransport, PeerBus

RIG = load_rig_config()
BAUD = 1_000_000


def small_rig(n: int = 6) -> RigConfig:
    """The shipped rig with its first ``n`` servos."""
    return dataclasses.replace(RIG, servos=RIG.servos[:n])


def tick_limits(rig: RigConfig) -> tuple[np.ndarray, np.ndarray]:
    """Each servo's lowest and highest goal in ticks (a reversed servo's limits swap)."""
    lo = np.array([min(deg_to_ticks(s, s.min_deg), deg_to_ticks(s, s.max_deg)) for s in rig.servos])
    hi = np.array([max(deg_to_ticks(s, s.min_deg), deg_to_ticks(s, s.max_deg)) for s in rig.servos])
    return lo, hi


def goals_received(sim: SimBus, rig: RigConfig) -> np.ndarray:
    """The Goal Position each emulated servo holds, in rig order (ticks)."""
    return np.array([sim.servo(s.id).goal for s in rig.servos])


def make_bus(
    rig: RigConfig | None = None, faults: FaultSpec | None = None, connect: bool = True,
    peer: PeerBus | None = None, **kw: object,
) -> tuple[DynamixelBus, EmulatorTransport, PeerBus]:
    """The driver on the in-process emulator through a fake transport (replies at wire
    time on a FakeClock): no pty, no thread."""
    rig = rig or small_rig()
    clock = FakeClock(100.0)
    peer = peer or PeerBus(rig, faults)
    transport = EmulatorTransport(peer, clock, BAUD)
    bus = DynamixelBus("fake:emulator", rig, baud=BAUD, clock=clock, transport=transport,
                       **kw)  # type: ignore[arg-type]
    if connect:
        bus.connect()
    return bus, transport, peer
