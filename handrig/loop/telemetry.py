"""What the loop publishes for anyone watching: an immutable :class:`LoopSnapshot`.

The loop thread calls :meth:`Telemetry.publish` after each cycle's work; at most
every ``every_s`` (1/30 s) it builds a snapshot of plain tuples from the loop's
state and swaps it in with one reference assignment. Readers on any thread call
:meth:`Telemetry.latest` and get the newest snapshot whole (never a half-written
one), without a lock and without touching the loop's live arrays.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from handrig.devices.glove.source import GloveSource
from handrig.devices.servo.bus import ServoBus, ServoState
from handrig.loop.modes import Mode, ModeMachine
from handrig.loop.ports import FloatArray
from handrig.loop.settings import LoopParts
from handrig.loop.stats import RunStats
from handrig.outputs.base import Output, OutputStatus
from handrig.pose.pipeline import POSE_NAMES

PUBLISH_EVERY_S = 1.0 / 30.0  # a snapshot at most this often (30 a second)
RATE_WINDOW_S = 1.0  # the loop rate is taken over about this long
RECENT_LATENCIES = 1000  # the latency percentiles are of the newest this many frames


@dataclass(frozen=True)
class LoopSnapshot:
    """The loop at one moment. Times in seconds on the loop's clock, angles in degrees.

    Per-servo tuples are in rig order (``servo_ids``, ``servo_joints``); a missing
    reading is None. ``pose_deg`` is the full pose last output (``curve_names``
    order: both hands' curves, then the wrists), NaN before the first.
    """

    t_s: float
    seq: int
    mode: str
    mode_reason: str
    rate_hz: float
    latency_p50_us: float | None
    latency_p99_us: float | None
    frames_lost: int
    cycles: int
    overruns: int
    elapsed_s: float = 0.0
    events: tuple[str, ...] = ()
    layers: tuple[str, ...] = ()  # the takes layered now: "GROUP <- TAKE (loop, on)"
    # the glove
    controls: tuple[float, ...] = ()
    raw: tuple[float, ...] = ()  # each control's channel's count (see SnapshotBuilder)
    control_names: tuple[str, ...] = ()
    inclination_deg: float = 0.0
    rotation_deg: float = 0.0
    glove_connected: bool = False
    glove_source: str = ""
    glove_frames_ok: int = 0
    glove_errors: int = 0
    glove_reconnects: int = 0
    glove_last_frame_age_s: float = math.inf
    glove_failure: str = ""
    # the pose
    pose_deg: tuple[float, ...] = ()
    curve_names: tuple[str, ...] = ()
    # the servos
    servo_ids: tuple[int, ...] = ()
    servo_joints: tuple[str, ...] = ()
    goals_deg: tuple[float, ...] = ()
    positions_deg: tuple[float | None, ...] = ()
    temperatures_c: tuple[float | None, ...] = ()
    currents_ma: tuple[float | None, ...] = ()
    hardware_errors: tuple[int, ...] = ()
    stale: tuple[bool, ...] = ()
    reading_ages_s: tuple[float, ...] = ()
    bus_port: str = ""
    bus_reads: int = 0
    bus_writes: int = 0
    bus_timeouts: int = 0
    bus_host_timeouts: int = 0  # of those, the host's (BusStats.host_timeouts)
    bus_errors: int = 0
    bus_left_out: int = 0  # servos left out at connect, not (yet) admitted
    bus_admitted: int = 0  # servos left out at connect, admitted when they answered
    # the outputs
    outputs: tuple[OutputStatus, ...] = ()


@dataclass(frozen=True, slots=True)
class CycleView:
    """What the cycle holds at one moment, for a snapshot (the live arrays: the
    snapshot copies them into tuples on the loop's thread).

    ``controls``: the controls of the newest sample; ``raw``: its raw channels (None
    before a sample); ``angles_deg``: the forearm's (inclination, rotation); ``pose``:
    the full pose last output (None before one); ``goals_deg``: the goals last
    written; ``state``: the newest reading (None before one); ``frame_s``: the
    newest glove frame's arrival on the loop's clock (NaN before one).
    """

    controls: FloatArray
    raw: FloatArray | None
    angles_deg: tuple[float, float]
    pose: FloatArray | None
    goals_deg: FloatArray
    state: ServoState | None
    frame_s: float
    layers: tuple[Any, ...] = ()  # the LayerStatus of each layer playing (immutable)


def _opt(values: np.ndarray | None, n: int) -> tuple[float | None, ...]:
    if values is None:
        return (None,) * n
    out = values.tolist()  # Python floats, in C
    if np.isnan(values).any():
        return tuple(v if v == v else None for v in out)
    return tuple(out)


class Telemetry:
    """The newest :class:`LoopSnapshot` (None before the first publication).

    ``publish(snapshot)`` swaps a built snapshot in; :meth:`offer` is what the loop
    calls each cycle: it builds one with ``build(t_s, seq)`` only when ``every_s``
    has passed since the last (or when ``force``).
    """

    def __init__(self, every_s: float = PUBLISH_EVERY_S) -> None:
        self.every_s = float(every_s)
        self._latest: LoopSnapshot | None = None
        self._seq = 0
        self._last_s = -math.inf

    def publish(self, snapshot: LoopSnapshot) -> None:
        """Make ``snapshot`` the newest (one reference assignment: never blocks)."""
        self._latest = snapshot
        self._last_s = snapshot.t_s

    def offer(self, now_s: float, build: Callable[[float, int], LoopSnapshot],
              force: bool = False) -> bool:
        """Build and publish a snapshot if one is due; True if it was."""
        if not force and now_s - self._last_s < self.every_s:
            return False
        self._seq += 1
        self.publish(build(now_s, self._seq))
        return True

    def latest(self) -> LoopSnapshot | None:
        """The newest snapshot (any thread)."""
        return self._latest


class SnapshotBuilder:
    """Builds :class:`LoopSnapshot` from the loop's parts (on the loop's thread).

    ``view`` gives what the cycle holds (:class:`CycleView`). The glove counts as
    connected while its newest frame is at most the glove timeout old and it reports
    no failure.
    """

    def __init__(self, parts: LoopParts, machine: ModeMachine, stats: RunStats,
                 started_s: Callable[[], float], view: Callable[[], CycleView],
                 outputs: Callable[[], tuple[object, ...]]) -> None:
        self.glove: GloveSource | None = parts.glove
        self.bus: ServoBus | None = parts.bus
        pipeline = self.pipeline = parts.pipeline
        self.machine = machine
        self.stats = stats
        self.started_s = started_s
        self.view = view
        self.outputs = outputs
        self.control_names = tuple(pipeline.expander.controls)
        self.raw_channels = tuple(int(i) for i in parts.raw_channels)
        """The raw channel driving each control, in control order (the glove file's
        ``[[channels]] index``; -1: none): the snapshot's ``raw`` is those channels'
        counts, beside their controls (NaN for none). Empty: ``raw`` is the glove's
        channels in their own order."""
        self.servo_joints = tuple(pipeline.servo_joints)
        n = len(self.servo_joints)
        self.servo_ids = (tuple(self.bus.ids) if self.bus is not None
                          else tuple(range(1, n + 1)))
        self._marks: list[tuple[float, int]] = []
        self.finished = False  # the run is over: the mode reads "stopped"

    def _rate(self, now: float, count: int) -> float:
        marks = self._marks
        marks.append((now, count))
        while len(marks) > 2 and now - marks[1][0] >= RATE_WINDOW_S:
            marks.pop(0)
        t0, c0 = marks[0]
        return (count - c0) / (now - t0) if now > t0 else math.nan

    def _mode(self) -> tuple[str, str]:
        stats, mode = self.stats, self.machine.mode
        name = "e-stop" if stats.estop else "stopped" if self.finished else mode.value
        events = stats.events
        reason = ""
        if name in ("stopping", "e-stop", "stopped"):
            reason = stats.stop_reason or (events[-1] if len(events) else "")
        elif mode in (Mode.RELAXING, Mode.RESUMING) and len(events):
            reason = events[-1]
        elif mode is Mode.WAITING:
            reason = "no glove frame yet: holding where the servos are"
        return name, reason

    def __call__(self, now: float, seq: int) -> LoopSnapshot:
        stats = self.stats
        p50 = p99 = None
        if len(stats.latencies_s):
            q50, q99 = stats.latencies_s.percentiles((50.0, 99.0), RECENT_LATENCIES)
            p50, p99 = q50 * 1e6, q99 * 1e6
        mode, reason = self._mode()
        view = self.view()
        n = len(self.servo_joints)
        glove_fields = self._glove()
        fresh = now - float(view.frame_s) <= self.machine.glove_timeout_s  # False for NaN
        glove_fields["glove_connected"] = fresh and not glove_fields.get("glove_failure")
        bus_fields = self._bus(view.state, now, n)
        pose_t = (tuple(np.asarray(view.pose, dtype=np.float64).tolist())
                  if view.pose is not None else (math.nan,) * len(POSE_NAMES))
        inc, rot = view.angles_deg
        started = self.started_s()
        return LoopSnapshot(
            t_s=now, seq=seq, mode=mode, mode_reason=reason,
            rate_hz=self._rate(now, stats.frames), latency_p50_us=p50, latency_p99_us=p99,
            frames_lost=(stats.frames_skipped + stats.frames_in_host_stalls
                         + int(glove_fields.pop("frames_lost"))),
            cycles=stats.frames, overruns=stats.overruns,
            elapsed_s=now - started if stats.frames else 0.0,
            events=tuple(stats.events[-3:]),
            layers=tuple(layer.describe() for layer in view.layers),
            controls=tuple(np.asarray(view.controls, dtype=np.float64).tolist()),
            raw=self._raw(view.raw),
            control_names=self.control_names,
            inclination_deg=float(inc), rotation_deg=float(rot),
            pose_deg=pose_t, curve_names=POSE_NAMES,
            servo_ids=self.servo_ids, servo_joints=self.servo_joints,
            goals_deg=tuple(np.asarray(view.goals_deg, dtype=np.float64).tolist()),
            outputs=tuple(o.status() for o in self.outputs() if isinstance(o, Output)),
            **glove_fields, **bus_fields,
        )

    def _raw(self, raw: FloatArray | None) -> tuple[float, ...]:
        if raw is None:
            return ()
        counts = np.asarray(raw, dtype=np.float64)
        if not self.raw_channels:
            return tuple(counts.tolist())
        return tuple(float(counts[i]) if 0 <= i < counts.size else math.nan
                     for i in self.raw_channels)

    def _glove(self) -> dict[str, Any]:
        glove = self.glove
        if glove is None:
            return {"frames_lost": 0}
        g = glove.stats()
        return {
            "frames_lost": g.frames_lost, "glove_source": glove.name,
            "glove_frames_ok": g.frames_ok,
            "glove_errors": g.errors, "glove_reconnects": g.reconnects,
            "glove_last_frame_age_s": g.time_since_last_good_s, "glove_failure": g.failure,
        }

    def _bus(self, state: ServoState | None, now: float, n: int) -> dict[str, Any]:
        out: dict[str, Any] = {}
        bus = self.bus
        if bus is not None:
            b = bus.stats
            out.update(bus_port=bus.port, bus_reads=b.reads, bus_writes=b.writes,
                       bus_timeouts=b.timeouts, bus_host_timeouts=b.host_timeouts,
                       bus_errors=b.crc_errors + b.malformed + b.status_errors,
                       bus_left_out=len(bus.left_out), bus_admitted=b.admissions)
        if state is None:
            out.update(positions_deg=(None,) * n, temperatures_c=(None,) * n,
                       currents_ma=(None,) * n, hardware_errors=(0,) * n,
                       stale=(False,) * n, reading_ages_s=(math.inf,) * n)
            return out
        since = max(0.0, now - float(state.timestamp_s))
        out.update(
            positions_deg=_opt(state.positions_deg, n),
            temperatures_c=_opt(state.temperatures_c, n),
            currents_ma=_opt(state.currents_ma, n),
            hardware_errors=tuple(np.asarray(state.hardware_errors, dtype=np.int64).tolist()),
            stale=tuple(np.asarray(state.stale, dtype=bool).tolist()),
            reading_ages_s=tuple((np.asarray(state.age_s, dtype=np.float64) + since).tolist()))
        return out
