"""The panel and the plain status line say how many read timeouts were the host's (a reply
held on its way, not lost on the bus), once, beside the count; none said when none were.
The panel's bus line still fits 80 columns with it, its stale servos shown whole."""

from __future__ import annotations

import io

from rich.console import Console

from handrig.app.panel import BusHealth, bus_line, plain_line
from handrig.app.parts import build_parts
from handrig.app.rig_snapshot import RigSnapshot
from handrig.clock import FakeClock
from tests.handrig.app.test_panel import SteadyGlove, screen, show_snapshot, warm_bus
from tests.helpers.loop import make_rig


def _wide(text: object) -> str:
    """The line as printed on a console wide enough not to crop it."""
    console = Console(width=200, record=True, file=io.StringIO(), force_terminal=True)
    console.print(text)
    return console.export_text().rstrip("\n")


def test_the_hosts_timeouts_are_named_beside_the_count() -> None:
    held = BusHealth("/dev/ttyUSB0", 50.0, 200.0, 19, 1, 2, 0.12, host_timeouts=17)
    line = _wide(bus_line(held))
    assert len(line) <= 80
    assert "timeouts 19 (host 17) errors 1 stale 2 (120 ms)" in line
    assert "timeouts 19 (host 17) errors 1" in "\n".join(screen(show_snapshot(bus=held)))
    assert "timeouts 19 (host 17) errors 1" in plain_line(show_snapshot(bus=held))
    plain = show_snapshot()
    assert "(host" not in "\n".join(screen(plain)) and "(host" not in plain_line(plain)
    line = _wide(bus_line(plain.bus))
    assert len(line) <= 80 and "timeouts 19  errors 1  stale 2 (worst 120 ms)" in line


def test_a_running_rigs_snapshot_carries_the_hosts_timeouts() -> None:
    parts = build_parts()
    clock = FakeClock()
    bus = warm_bus(tuple(parts.pipeline.servo_joints), clock)
    bus.stats.host_timeouts = 3  # of its 4
    rig = make_rig(parts, SteadyGlove(clock), bus, clock)
    snapshot = RigSnapshot(rig, glove_source="/dev/ttyACM0")
    rig.run(frames=20)
    snap = snapshot()
    assert (snap.bus.timeouts, snap.bus.host_timeouts) == (4, 3)
    assert "timeouts 4 (host 3)" in plain_line(snap)
