"""The panel's snapshot of a running rig (:class:`RigSnapshot`), from its telemetry.

Reads only ``rig.telemetry.latest()`` (a frozen
:class:`~handrig.loop.telemetry.LoopSnapshot` the loop publishes) and the rig's
clock, never the loop's live arrays: the panel's thread and the loop's share
nothing that changes.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from typing import Protocol

from handrig.app.panel import NAN, BusHealth, GloveLink, PanelSnapshot, ServoLine
from handrig.clock import Clock
from handrig.loop.telemetry import LoopSnapshot, Telemetry
from handrig.outputs.base import PanelCell


class Watched(Protocol):
    """What the panel needs of a rig: its clock and its telemetry."""

    clock: Clock
    telemetry: Telemetry


class _Rate:
    """Events per second of a growing counter, over the last ``window_s`` or more."""

    def __init__(self, window_s: float = 1.0) -> None:
        self.window_s = window_s
        self._marks: list[tuple[float, int]] = []
        self.value = NAN

    def update(self, now: float, count: int) -> float:
        if self._marks and now <= self._marks[-1][0]:
            return self.value  # the same snapshot again
        self._marks.append((now, count))
        while len(self._marks) > 2 and now - self._marks[1][0] >= self.window_s:
            self._marks.pop(0)
        t0, c0 = self._marks[0]
        if now - t0 > 0:
            self.value = (count - c0) / (now - t0)
        return self.value


def _nan(value: float | None) -> float:
    return NAN if value is None else float(value)


class RigSnapshot:
    """``RigSnapshot(rig)()``: the :class:`PanelSnapshot` of a running rig.

    Built from the newest telemetry snapshot; ages and the elapsed time are carried
    forward to the clock's now. Rates are taken over the last second between
    snapshots. ``glove_source``, ``temperature_limit_c`` (servo id -> limit) and
    ``heat_c`` (``[heat]`` warn_c, act_c: the temperature colours) are used when
    given; ``keys``: whether a :class:`~handrig.app.keys.KeyReader` is listening (the
    panel says so either way).
    """

    def __init__(self, rig: Watched, *, glove_source: str = "",
                 temperature_limit_c: Mapping[int, float] | None = None,
                 heat_c: tuple[float, float] = (NAN, NAN),
                 keys: bool = False, show: str = "") -> None:
        self.rig = rig
        self.glove_source = glove_source
        self.keys = keys
        self.show = show
        self.temperature_limit_c = dict(temperature_limit_c or {})
        self.warn_c, self.act_c = heat_c
        self._rates = {k: _Rate() for k in ("glove", "reads", "writes")}
        self._output_rates: dict[int, _Rate] = {}  # by the output's place in the loop's

    def __call__(self) -> PanelSnapshot:
        snap = self.rig.telemetry.latest()
        if snap is None:
            return PanelSnapshot(reason="starting", keys=self.keys,
                                 glove=GloveLink(self.glove_source), show=self.show)
        since = max(0.0, self.rig.clock.now() - snap.t_s)
        return PanelSnapshot(
            mode=snap.mode, reason=snap.mode_reason,
            elapsed_s=snap.elapsed_s + since if snap.cycles else 0.0,
            loop_rate_hz=snap.rate_hz, overruns=snap.overruns,
            latency_p50_us=_nan(snap.latency_p50_us), latency_p99_us=_nan(snap.latency_p99_us),
            glove=self._glove(snap, since), bus=self._bus(snap, since),
            servos=self._servos(snap), outputs=self._outputs(snap), events=snap.events,
            keys=self.keys, show=self.show, layers=snap.layers)

    def _glove(self, s: LoopSnapshot, since: float) -> GloveLink:
        return GloveLink(
            source=self.glove_source or s.glove_source,
            rate_hz=self._rates["glove"].update(s.t_s, s.glove_frames_ok),
            frames_ok=s.glove_frames_ok, errors=s.glove_errors,
            last_frame_age_s=s.glove_last_frame_age_s, reconnects=s.glove_reconnects,
            failure=s.glove_failure)

    def _bus(self, s: LoopSnapshot, since: float) -> BusHealth:
        ages = [a for a, stale in zip(s.reading_ages_s, s.stale, strict=False) if stale]
        worst = max(ages) + since if ages else 0.0
        return BusHealth(
            port=s.bus_port, read_rate_hz=self._rates["reads"].update(s.t_s, s.bus_reads),
            write_rate_hz=self._rates["writes"].update(s.t_s, s.bus_writes),
            timeouts=s.bus_timeouts, host_timeouts=s.bus_host_timeouts, errors=s.bus_errors,
            stale_servos=len(ages),
            stale_worst_age_s=worst if math.isfinite(worst) else 0.0,
            left_out=s.bus_left_out, admitted=s.bus_admitted)

    def _servos(self, s: LoopSnapshot) -> tuple[ServoLine, ...]:
        n = len(s.servo_joints)

        def at(values: tuple[float | None, ...], i: int) -> float:
            return _nan(values[i]) if i < len(values) else NAN

        return tuple(
            ServoLine(s.servo_ids[i], joint, at(s.goals_deg, i), at(s.positions_deg, i),
                      bool(s.stale[i]) if i < len(s.stale) else False,
                      at(s.temperatures_c, i),
                      self.temperature_limit_c.get(s.servo_ids[i], NAN),
                      self.warn_c, self.act_c,
                      at(s.currents_ma, i),
                      s.hardware_errors[i] if i < len(s.hardware_errors) else 0)
            for i, joint in enumerate(s.servo_joints[:n]))

    def _outputs(self, s: LoopSnapshot) -> tuple[PanelCell, ...]:
        """Each output's own cell (:meth:`~handrig.outputs.base.OutputStatus.cell`), its
        rate filled in when it shows one."""
        cells = []
        for i, out in enumerate(s.outputs):
            cell = out.cell()
            if cell.rate:
                rate = self._output_rates.setdefault(i, _Rate())
                cell = dataclasses.replace(cell, rate_hz=rate.update(s.t_s, out.frames_written))
            cells.append(cell)
        return tuple(cells)


HAND_LABELS = {"ri": "right", "le": "left"}


class HandsSnapshot:
    """The panel of a session's hands: with several, a line per hand (its mode, glove
    and latency), the servos of all, the first hand's bus, every hand's outputs (the
    shared ones run on the first hand's loop; a hand's glove take on its own), the events of
    all; with one, that hand's panel as it is. ``sides``: hand -> the hand's
    :class:`RigSnapshot`, right first."""

    def __init__(self, sides: Mapping[str, RigSnapshot], *, keys: bool = False,
                 show: str = "", cues: Callable[[], tuple[str, ...]] | None = None) -> None:
        self.sides = dict(sides)
        self.keys = keys
        self.show = show
        self.cues = cues  # the last few cues taken, each naming its source

    def __call__(self) -> PanelSnapshot:
        snap = self._hands()
        return snap if self.cues is None else dataclasses.replace(snap, cues=self.cues())

    def _hands(self) -> PanelSnapshot:
        snaps = {h: side() for h, side in self.sides.items()}
        first = next(iter(snaps.values()))
        if len(snaps) == 1:
            return first
        modes = {s.mode for s in snaps.values()}
        mode = first.mode if len(modes) == 1 else "/".join(s.mode for s in snaps.values())
        reasons = [f"{HAND_LABELS.get(h, h)}: {s.reason}" for h, s in snaps.items()
                   if s.reason]
        lines = tuple(hand_line(HAND_LABELS.get(h, h), s) for h, s in snaps.items())
        events = tuple(e for s in snaps.values() for e in s.events)
        return PanelSnapshot(
            mode=mode, reason="; ".join(reasons), elapsed_s=first.elapsed_s,
            loop_rate_hz=first.loop_rate_hz,
            overruns=sum(s.overruns for s in snaps.values()),
            latency_p50_us=max(s.latency_p50_us for s in snaps.values()),
            latency_p99_us=max(s.latency_p99_us for s in snaps.values()),
            glove=first.glove, bus=first.bus,
            servos=tuple(sv for s in snaps.values() for sv in s.servos),
            outputs=tuple(c for s in snaps.values() for c in s.outputs), events=events[-6:],
            keys=self.keys, show=self.show,
            hands=lines, layers=tuple(dict.fromkeys(x for s in snaps.values() for x in s.layers)))


def hand_line(label: str, s: PanelSnapshot) -> str:
    """One hand of a two-hand run in a line: mode, glove (rate, errors, age), latency."""
    g = s.glove
    age = g.last_frame_age_s
    age_text = "-" if not math.isfinite(age) else f"{age * 1000:.0f} ms"
    lat = ("-" if not math.isfinite(s.latency_p50_us)
           else f"{s.latency_p50_us:.0f}/{s.latency_p99_us:.0f} us")
    rate = "-" if not math.isfinite(g.rate_hz) else f"{g.rate_hz:.0f} Hz"
    return (f"{label:<5}  {s.mode:<8} glove {rate} err {g.errors} last {age_text}  "
            f"p50/p99 {lat}  over {s.overruns}")
