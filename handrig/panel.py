"""The live terminal panel of ``handrig run``: rates, latency, per-servo state.

Drawn by :mod:`rich` from its own thread a few times a second, reading the rig's
counters; the realtime loop never waits for the terminal.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
from rich.console import Console, Group
from rich.live import Live
from rich.table import Table
from rich.text import Text

from handrig.rig import Rig


def _fmt(value: Any, spec: str = ".0f") -> str:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return "-"
    return "-" if np.isnan(v) else format(v, spec)


def render(rig: Rig) -> Group:
    """One frame of the panel for the rig's current counters."""
    s = rig.stats
    elapsed = max(rig.clock.now() - rig.started_at, 1e-9) if rig.started_at else 0.0
    rate = s.frames / elapsed if elapsed else 0.0
    lat = s.latencies_s[-2000:]
    p50 = np.percentile(lat, 50) * 1e6 if lat else float("nan")
    p99 = np.percentile(lat, 99) * 1e6 if lat else float("nan")
    head = Text.assemble(
        ("handrig run  ", "bold"),
        (f"{rig.mode.value}  ", "green" if rig.mode.value == "running" else "yellow"),
        f"{s.frames} frames  {rate:.1f} Hz  latency p50 {_fmt(p50)} us  p99 {_fmt(p99)} us  ",
        f"overruns {s.overruns}  clamps {rig.pipeline.clamps}  "
        f"tracking rms {_fmt(s.tracking_rms_deg, '.2f')} deg",
    )
    table = Table(expand=False, show_edge=False)
    for col in ("id", "joint", "goal deg", "present deg", "temp C", "current mA", "error"):
        table.add_column(col, justify="right" if col not in ("joint", "error") else "left")
    state = rig.last_state
    ids = getattr(state, "ids", None) or list(range(1, len(rig.pipeline.servo_joints) + 1))
    for i, joint in enumerate(rig.pipeline.servo_joints):
        def field(name: str, i: int = i) -> Any:
            arr = getattr(state, name, None)
            return None if arr is None else arr[i]
        stale = field("stale")
        err = field("errors")
        table.add_row(
            str(ids[i]), joint, _fmt(rig.pipeline.targets[i], ".1f"),
            ("stale" if stale else _fmt(field("positions_deg"), ".1f")),
            _fmt(field("temperatures_c")), _fmt(field("currents_ma")),
            "" if not err else f"0x{int(err):02x}",
        )
    events = Text("\n".join(s.events[-4:]), style="yellow")
    return Group(head, table, events)


class LivePanel:
    """Context manager that redraws :func:`render` at ``refresh_hz`` while the rig runs."""

    def __init__(self, rig: Rig, refresh_hz: float = 4.0, console: Console | None = None) -> None:
        self.rig = rig
        self.refresh_s = 1.0 / refresh_hz
        self.console = console or Console()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _loop(self) -> None:
        with Live(render(self.rig), console=self.console, auto_refresh=False) as live:
            while not self._stop.wait(self.refresh_s):
                live.update(render(self.rig), refresh=True)
            live.update(render(self.rig), refresh=True)

    def __enter__(self) -> LivePanel:
        self._thread = threading.Thread(target=self._loop, name="handrig-panel", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
