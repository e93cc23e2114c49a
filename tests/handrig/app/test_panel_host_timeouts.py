"""The panel and the plain status line say how many read timeouts were the host's (a reply
held on its way, not lost on the bus), once, beside the count; none said when none were.
The panel's bus line still fits 80 columns with it, its stale servos shown whole."""

from __future__ import annotations

import io
import math

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


def test_the_bus_line_fits_80_columns_after_hours_of_timeouts() -> None:
    """A show of hours may count thousands of timeouts: the bus line tightens step by step
    (one space, no "worst", a shorter port, counts in thousands, no stale age, no port,
    the servos left out and admitted first) and stays within 80 columns, the counts still
    readable and the servos left out and admitted the last to go."""
    def line(timeouts: int, host: int, errors: int, rate: float = 50.0, age: float = 0.12,
             **kw: int) -> str:
        b = BusHealth("/dev/ttyUSB0", rate, 200.0, timeouts, errors, 20, age,
                      host_timeouts=host, **kw)
        text = _wide(bus_line(b))
        assert len(text) <= 80, text
        return text

    assert "/dev/ttyUSB0 reads 50/s timeouts 1234 errors 5 stale 20 (120 ms)" in line(
        1234, 0, 5)
    assert "…tyUSB0 reads 50/s timeouts 1234 (host 1200) errors 5 stale 20" in line(
        1234, 1200, 5)
    assert "timeouts 12k (host 11k) errors 123 stale 20 (120 ms)" in line(12345, 11999, 123)
    # the servos left out and admitted outlast the port and the stale readings' age
    assert line(40, 2, 0, rate=1266.0, left_out=1, admitted=1).endswith(
        "timeouts 40 (host 2) errors 0 stale 20 out 1 admitted 1")
    assert line(1234, 1200, 5, rate=1266.0, age=math.inf, left_out=1).endswith(
        "(host 1200) errors 5 stale 20 out 1")
    # at the tightest the servos left out and admitted come first: the cut takes the end
    assert line(1234, 1200, 1234, rate=1266.0, left_out=1, admitted=1) == (
        "bus out 1 admitted 1 reads 1266/s timeouts 1234 (host 1200) errors 1234 stale 20")
    cut = line(999999, 999999, 999999, rate=1266.0, age=12.0, left_out=20, admitted=20)
    assert cut.startswith("bus out 20 admitted 20 reads 1266/s") and cut.endswith("…")
    for timeouts in (0, 9, 99, 999, 9999, 99999, 999999):
        line(timeouts, timeouts // 2, timeouts)
        line(timeouts, 0, 0, left_out=1, admitted=1)
