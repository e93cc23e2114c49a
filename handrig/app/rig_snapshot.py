"""The panel's snapshot of a running rig (:class:`RigSnapshot`)."""

from __future__ import annotations

import contextlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from handrig.app.panel import NAN, BusHealth, GloveLink, Outputs, PanelSnapshot, ServoLine


class _Rate:
    """Events per second of a growing counter, over the last ``window_s`` or more."""

    def __init__(self, window_s: float = 1.0) -> None:
        self.window_s = window_s
        self._marks: list[tuple[float, int]] = []
        self.value = NAN

    def update(self, now: float, count: int) -> float:
        self._marks.append((now, count))
        while len(self._marks) > 2 and now - self._marks[1][0] >= self.window_s:
            self._marks.pop(0)
        t0, c0 = self._marks[0]
        if now - t0 > 0:
            self.value = (count - c0) / (now - t0)
        return self.value


class RigSnapshot:
    """``RigSnapshot(rig)()``: the :class:`PanelSnapshot` of a running rig.

    Reads the rig's counters, its glove's and bus's statistics, its newest
    servo state, and the VMC sender and recorder among its outputs. Rates are
    taken over the last second between calls. ``glove_source`` and
    ``temperature_limit_c`` (servo id -> limit) are shown when given; ``keys``:
    whether a :class:`KeyReader` is listening (the panel says so either way).
    """

    def __init__(self, rig: Any, *, glove_source: str = "",
                 temperature_limit_c: Mapping[int, float] | None = None,
                 keys: bool = False) -> None:
        self.rig = rig
        self.glove_source = glove_source
        self.keys = keys
        self.temperature_limit_c = dict(temperature_limit_c or {})
        self._rates = {k: _Rate() for k in ("loop", "glove", "reads", "writes", "vmc")}

    def __call__(self) -> PanelSnapshot:
        rig = self.rig
        now = rig.clock.now()
        stats = rig.stats
        elapsed = now - rig.started_at if stats.frames else 0.0  # started_at is set by then
        lat = np.asarray(stats.latencies_s[-2000:], dtype=np.float64)
        p50, p99 = (np.percentile(lat, [50, 99]) * 1e6) if lat.size else (NAN, NAN)
        mode = getattr(rig.mode, "value", str(rig.mode))
        if stats.estop:
            mode = "e-stop"
        reason = ""
        if mode in ("stopping", "e-stop"):
            reason = stats.stop_reason or (stats.events[-1] if stats.events else "")
        elif mode in ("relaxing", "resuming") and stats.events:
            reason = stats.events[-1]
        elif mode == "waiting":
            reason = "no glove frame yet: holding where the servos are"
        return PanelSnapshot(
            mode=mode, reason=reason, elapsed_s=elapsed,
            loop_rate_hz=self._rates["loop"].update(now, stats.frames),
            overruns=stats.overruns, latency_p50_us=float(p50), latency_p99_us=float(p99),
            glove=self._glove(now), bus=self._bus(now), servos=self._servos(now),
            outputs=self._outputs(now), events=tuple(stats.events[-3:]), keys=self.keys,
        )

    def _glove(self, now: float) -> GloveLink:
        stats_fn = getattr(self.rig.glove, "stats", None)
        if stats_fn is None:
            return GloveLink(self.glove_source)
        g = stats_fn()
        return GloveLink(
            source=self.glove_source or str(getattr(self.rig.glove, "port", "")),
            rate_hz=self._rates["glove"].update(now, g.frames_ok), frames_ok=g.frames_ok,
            errors=g.errors, last_frame_age_s=g.time_since_last_good_s,
            reconnects=g.reconnects, failure=g.failure)

    def _bus(self, now: float) -> BusHealth:
        bus = self.rig.bus
        b = getattr(bus, "stats", None)
        state = self.rig.last_state
        stale_n, worst = 0, 0.0
        if state is not None:
            stale = np.asarray(state.stale, dtype=bool)
            stale_n = int(stale.sum())
            if stale_n:
                since = max(0.0, now - float(state.timestamp_s))
                worst = float(np.max(np.asarray(state.age_s)[stale])) + since
        if b is None:
            return BusHealth(stale_servos=stale_n, stale_worst_age_s=worst)
        return BusHealth(
            port=str(getattr(bus, "port", "")),
            read_rate_hz=self._rates["reads"].update(now, b.reads),
            write_rate_hz=self._rates["writes"].update(now, b.writes),
            timeouts=b.timeouts, errors=b.crc_errors + b.malformed + b.status_errors,
            stale_servos=stale_n, stale_worst_age_s=worst)

    def _servos(self, now: float) -> tuple[ServoLine, ...]:
        rig = self.rig
        joints = tuple(rig.pipeline.servo_joints)
        ids = list(getattr(rig.bus, "ids", None) or range(1, len(joints) + 1))
        goals = np.asarray(rig.pipeline.targets, dtype=np.float64)
        state = rig.last_state

        def column(name: str, default: float = NAN) -> np.ndarray:
            arr = getattr(state, name, None)
            return (np.full(len(joints), default) if arr is None
                    else np.asarray(arr, dtype=np.float64))

        pos, temp, cur = (column("positions_deg"), column("temperatures_c"),
                          column("currents_ma"))
        hw = column("hardware_errors", 0.0)
        stale = column("stale", 0.0)
        return tuple(
            ServoLine(int(ids[i]), joint, float(goals[i]), float(pos[i]), bool(stale[i]),
                      float(temp[i]), self.temperature_limit_c.get(int(ids[i]), NAN),
                      float(cur[i]), int(hw[i]))
            for i, joint in enumerate(joints))

    def _outputs(self, now: float) -> Outputs:
        vmc_target, vmc_rate, vmc_err = "", NAN, 0
        rec_path, rec_bytes, rec_s = "", 0, 0.0
        for out in self.rig.outputs:
            address = getattr(out, "address", None)
            if address is not None and hasattr(out, "bundles_sent"):
                vmc_target = f"{address[0]}:{address[1]}"
                vmc_rate = self._rates["vmc"].update(now, out.bundles_sent)
                vmc_err = int(getattr(out, "errors", 0))
            elif hasattr(out, "n_frames") and hasattr(out, "path"):
                rec_path = str(out.path)
                rec_s = out.n_frames / float(getattr(out, "rate_hz", 0.0) or 1.0)
                rec_bytes = _bytes_on_disk(Path(out.path))
        return Outputs(vmc_target, vmc_rate, vmc_err, rec_path, rec_bytes, rec_s)


def _bytes_on_disk(path: Path) -> int:
    """Size of a recording being written (its ``.partial`` file until it is closed)."""
    total = 0
    for p in (path, path.with_name(path.name + ".partial")):
        with contextlib.suppress(OSError):
            total = max(total, p.stat().st_size)
    return total


