"""The panel and the plain status line say how many read timeouts were the host's (a reply
held on its way, not lost on the bus), once, beside the count; none said when none were."""

from __future__ import annotations

from handrig.app.panel import BusHealth, plain_line
from tests.handrig.app.test_panel import screen, show_snapshot


def test_the_hosts_timeouts_are_named_beside_the_count() -> None:
    held = BusHealth("/dev/ttyUSB0", 50.0, 200.0, 19, 1, 2, 0.12, host_timeouts=17)
    lines = screen(show_snapshot(bus=held))
    assert max(len(line) for line in lines) <= 80
    text = "\n".join(lines)
    assert "reads 50/s  timeouts 19 (host 17)  errors 1" in text
    assert "timeouts 19 (host 17) errors 1" in plain_line(show_snapshot(bus=held))
    plain = show_snapshot()
    assert "(host" not in "\n".join(screen(plain)) and "(host" not in plain_line(plain)
