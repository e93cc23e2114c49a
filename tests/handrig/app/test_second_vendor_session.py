"""A second servo vendor runs a whole session, not only the loop.

The toy vendor of ``tests/handrig/loop/test_second_vendor.py`` (the ServoBus ABC alone)
is handed to :func:`handrig.app.session.run_live` as the bus of a real session: the
shipped rig's pipeline, map and sag grid, the demo recording played as the glove, the
session's own torque context, signals, summary and torque read back. On a fake clock,
so the run takes a fraction of a second: start, a servo that goes silent and comes
back ([silence] tiers), a relax and resume, the stop with torque off, the summary.
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Iterator
from typing import Any

import numpy as np

from handrig.app.factory import OpenedBus
from handrig.app.parts import RigParts, build_parts
from handrig.app.session import LiveOptions, run_live
from handrig.clock import Clock, FakeClock
from handrig.config.rig import LoopConfig, SilenceConfig
from handrig.devices.glove import ReplayGlove
from handrig.devices.glove_recording import read_glove_recording
from sim.demo_recording import DEMO_RECORDING
from tests.handrig.loop.test_second_vendor import ToyBus

SILENT = 6  # rig index of the servo that goes quiet (id 7)


class ToyVendorBus(ToyBus):
    """The toy vendor, with the one hook a session's summary wants: torque read back
    (its servos report their torque flag)."""

    def confirm_torque_off(self, budget_s: float) -> tuple[bool | None, list[str]]:
        if self.torque_on:
            return False, [f"{self.describe(i)}: torque still on" for i in range(self.n_servos)]
        return True, []


def _parts() -> RigParts:
    parts = build_parts()
    loop = dataclasses.replace(parts.rig_config.loop, mode="fixed", rate_hz=200.0,
                               realtime_priority=0, pin_cpu=False, relax_time_s=0.5,
                               resume_time_s=0.2)
    assert isinstance(loop, LoopConfig)
    silence = SilenceConfig(warn_s=0.05, hold_s=0.1, action_s=0.2, action="continue")
    rig = dataclasses.replace(parts.rig_config, loop=loop, silence=silence)
    return dataclasses.replace(parts, rig_config=rig)


def _session(bus_class: type[ToyBus], clock: FakeClock, *, script: bool = True,
             modes: dict[float, str] | None = None
             ) -> tuple[dict[str, Any], list[ToyBus], list[str], bool]:
    parts = _parts()
    servos = parts.rig_config.servos
    buses: list[ToyBus] = []
    opened_with: list[str | None] = []

    @contextlib.contextmanager
    def open_toy(spec: str | None, on: RigParts, clk: Clock, **kw: Any) -> Iterator[OpenedBus]:
        assert clk is clock
        bus = bus_class(tuple(s.joint for s in on.rig_config.servos),
                        np.array([s.min_deg for s in servos]),
                        np.array([s.max_deg for s in servos]), clock)
        bus.port = "toy0"
        bus._pos[:] = 0.5 * (bus.low + bus.high)  # where the servos rest at the start
        buses.append(bus)
        opened_with.append(spec)
        try:
            yield OpenedBus(bus, "toy0")
        finally:
            bus.close()

    def on_hands(rigs: dict[str, Any], every: Any) -> None:
        (rig,) = rigs.values()

        def steps(t_s: float, pose: np.ndarray) -> None:
            bus = buses[0]
            if abs(t_s - 0.5) < 1e-9:
                bus.silent.add(SILENT)
            if abs(t_s - 1.0) < 1e-9:
                bus.silent.clear()
            if abs(t_s - 1.5) < 1e-9 or abs(t_s - 2.0) < 1e-9:
                every.toggle_relax()  # relax, then resume, as the space key does
            for at in (1.4, 1.9, 2.5):
                if modes is not None and abs(t_s - at) < 1e-9:
                    modes[at] = rig.mode.name
        if script:
            rig.outputs = (*rig.outputs, steps)

    lines: list[str] = []
    rec = read_glove_recording(DEMO_RECORDING)
    result = run_live(parts, LiveOptions(
        glove=f"replay:{DEMO_RECORDING}", take=lambda clk: ReplayGlove(rec, clk, loop=True),
        bus="toy0", duration_s=3.0, log=lines.append, on_hands=on_hands), clock,
        open_bus=open_toy)
    assert opened_with == ["toy0"]
    return result.summary, buses, lines, result.started


def test_a_toy_vendor_runs_a_whole_session_and_stops_with_torque_off() -> None:
    clock = FakeClock(10.0)
    modes: dict[float, str] = {}
    summary, buses, lines, started = _session(ToyVendorBus, clock, modes=modes)
    assert started and "error" not in summary, summary.get("error")
    (bus,) = buses
    # the session's torque context: on for the run, off once, read back off
    assert not bus.torque_on and bus.torque_offs == 1 and not bus.connected
    assert summary["torque_off"] is True and "torque_off_unconfirmed" not in summary
    # 3 s at 200 Hz, then the ease to relaxed; every goal within the servos' limits
    assert 600 <= summary["frames"] <= 600 + 0.5 * 200 + 5
    goals = np.array(bus.goals)
    assert (goals >= bus.low - 1e-9).all() and (goals <= bus.high + 1e-9).all()
    assert summary["ease_s"] == 0.5 and summary["stop_reason"] == "3 s done"
    # the silent servo: warned, held, back; the relax and resume
    events = summary["events"]
    assert any(e.startswith("no valid reply from servo 7") for e in events), events
    assert any(e.startswith("holding servo 7") for e in events), events
    assert any(e.startswith("servo 7") and "answers again" in e for e in events), events
    silence = summary["silence"]
    assert {k: silence[k] for k in ("silences", "held", "recoveries", "admitted")} == {
        "silences": 1, "held": 1, "recoveries": 1, "admitted": 0}
    # what happened to whom: servo 7 alone, no read unanswered whole
    assert list(silence["servos"]) == ["servo 7 (riIndexMCPy)"], silence
    assert silence["reads_unanswered_whole"] == 0, silence
    assert modes == {1.4: "RUNNING", 1.9: "RELAXING", 2.5: "RUNNING"}, modes
    # the summary: the bus's counters and the glove's, the same keys as any hand's
    assert summary["bus"]["writes"] == len(bus.goals) and summary["bus"]["reads"] > 100
    assert summary["glove"]["frames_used"] > 300 and summary["glove_source"].startswith(
        "replay:")
    assert summary["latency_us"]["samples"] == summary["glove"]["frames_used"] > 300
    assert any("servo bus toy0: 20 servos commissioned" in line for line in lines), lines


def test_a_vendor_that_cannot_read_torque_back_says_so_in_the_summary() -> None:
    summary, buses, _, started = _session(ToyBus, FakeClock(10.0), script=False)
    assert started and "error" not in summary, summary.get("error")
    assert not buses[0].torque_on and buses[0].torque_offs == 1  # off all the same
    assert summary["torque_off"] is None  # not confirmed: the bus cannot say
    unconfirmed = summary["torque_off_unconfirmed"]
    assert len(unconfirmed) == 20 and all("cannot read torque" in u for u in unconfirmed)
