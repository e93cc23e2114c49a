"""The live rig: a fixed-rate loop from glove to servos, with its safety behaviour.

``Rig(glove, bus, pipeline, clock, ...)`` runs cycles at ``rate_hz`` on the
injected :class:`~handrig.clock.Clock`. Each cycle it takes the newest glove
sample without blocking, turns it into servo targets through the
:class:`~handrig.pipeline.PosePipeline`, hands one Sync Write to the bus, and
every ``read_every`` cycles reads the servos' present state back.

Safety (what a puppeteer relies on during a show):

* glove silent or garbled for longer than ``glove_timeout_s``: the puppet eases
  to the relaxed pose over ``relax_time_s`` and the rig says so; it resumes when
  good frames come back;
* the glove's e-stop button, Ctrl-C or SIGTERM: ease to the relaxed pose, then
  stop (the bus's torque context then disables torque); a second signal stops
  at once;
* a lost servo port: stop cleanly with the device's message;
* nothing outside the limits: the pipeline clamps to joint and servo limits, and
  the bus clamps again to each servo's configured range.
"""

from __future__ import annotations

import copy
import enum
import gc
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from handrig.clock import Clock
from handrig.errors import DeviceError
from handrig.pipeline import PosePipeline

FloatArray = NDArray[np.float64]


class SampleLike(Protocol):
    raw: FloatArray
    quat: FloatArray | None
    estop: bool
    host_time_s: float


class GloveLike(Protocol):
    def latest(self) -> Any: ...


class ControlsFromRaw(Protocol):
    def __call__(self, raw: FloatArray, t_s: float, out: FloatArray) -> FloatArray: ...


class OrientationLike(Protocol):
    def __call__(self, sample: Any) -> tuple[float, float]: ...


class BusLike(Protocol):
    def write_goals_deg(self, goals_deg: FloatArray) -> int: ...

    def read_state(self, deadline_s: float | None = None) -> Any: ...


class Mode(enum.Enum):
    WAITING = "waiting"  # no glove frame yet: hold where the servos are
    RUNNING = "running"
    RELAXING = "relaxing"  # glove lost: easing to relaxed, resumes when the glove is back
    STOPPING = "stopping"  # e-stop or stop request: easing to relaxed, then the loop ends


@dataclass
class RunStats:
    """What a run measured. Times in seconds unless the name says otherwise."""

    frames: int = 0
    duration_s: float = 0.0
    glove_samples: int = 0
    latencies_s: list[float] = field(default_factory=list)
    periods_s: list[float] = field(default_factory=list)
    overruns: int = 0
    overrun_max_s: float = 0.0
    missed_cycles: int = 0
    clamps: int = 0  # full-pose values clamped to joint limits (both hands)
    servo_clamps: int = 0  # servo targets clamped to joint or servo limits
    nonfinite: int = 0  # NaN/inf servo targets replaced by the last good target
    slewed: int = 0
    bus_clamps: int = 0
    reads: int = 0
    stale_reads: int = 0
    tracking_sq_sum: float = 0.0
    tracking_n: int = 0
    tracking_max_deg: float = 0.0
    relax_events: int = 0  # times the glove was lost and the puppet eased to relaxed
    estop: bool = False
    stop_reason: str = ""
    events: list[str] = field(default_factory=list)

    @property
    def rate_hz(self) -> float:
        return self.frames / self.duration_s if self.duration_s > 0 else 0.0

    def latency_us(self, q: float) -> float:
        if not self.latencies_s:
            return math.nan
        return float(np.percentile(np.asarray(self.latencies_s), q) * 1e6)

    @property
    def jitter_us(self) -> float:
        """Standard deviation of the cycle period."""
        if len(self.periods_s) < 2:
            return math.nan
        return float(np.std(np.asarray(self.periods_s)) * 1e6)

    @property
    def tracking_rms_deg(self) -> float:
        return math.sqrt(self.tracking_sq_sum / self.tracking_n) if self.tracking_n else math.nan


class Rig:
    """The realtime loop. Dependencies are passed in; nothing here opens a device."""

    def __init__(
        self,
        glove: GloveLike,
        bus: BusLike,
        pipeline: PosePipeline,
        clock: Clock,
        *,
        controls_from_raw: ControlsFromRaw,
        orientation: OrientationLike,
        rate_hz: float = 200.0,
        read_every: int = 4,
        glove_timeout_s: float = 0.25,
        relax_time_s: float = 1.0,
        outputs: Sequence[Callable[[float, FloatArray], None]] = (),
        log: Callable[[str], None] = print,
        warm_s: float = 0.00035,
        profile: bool = False,
    ) -> None:
        self.glove = glove
        self.bus = bus
        self.pipeline = pipeline
        self.clock = clock
        self.controls_from_raw = controls_from_raw
        self.orientation = orientation
        self.period_s = 1.0 / rate_hz
        self.read_every = max(1, int(read_every))
        self.glove_timeout_s = glove_timeout_s
        self.relax_time_s = relax_time_s
        self.outputs = tuple(outputs)
        self.log = log
        self.stats = RunStats()
        self.mode = Mode.WAITING
        self._stop_requests = 0
        self.started_at = 0.0
        self._controls = np.zeros(len(pipeline.expander.controls))
        self._orientation = (0.0, 0.0)
        self._blend_from = np.zeros(len(pipeline.servo_joints))
        self._pose_from = np.zeros(len(pipeline.pose))
        self._blend = 0.0
        self._out_pose = np.zeros(len(pipeline.pose))
        self._blend_t0: float | None = None  # set on the first easing cycle
        self._sent = np.zeros(len(pipeline.servo_joints))  # the goals last written
        self._accounted = False  # whether pipeline.pose holds an active pose yet
        self.last_state: Any = None  # the newest ServoState read back
        # Rehearsal: ``warm_s`` before each deadline the critical path runs once on
        # scratch copies (same code, separate state), so the code that handles the next
        # glove frame is warm in the CPU caches when the frame is read. On this VM a
        # cold pass cost 4-6x a warm one.
        self.warm_s = max(0.0, float(warm_s))
        # profile=True: per glove frame, clock times after each stage of the critical path
        # (read, controls, orientation, targets, write), for bench_rig's breakdown.
        self.profile = profile
        self.stage_times: list[tuple[float, ...]] = []
        self._prepared = False  # prepare() ran: garbage collected, start-up heap frozen
        self._last_sample: Any = None
        if self.warm_s > 0:
            shared: dict[int, Any] = {id(pipeline.expander): pipeline.expander}
            if pipeline.sag is not None:
                shared[id(pipeline.sag)] = pipeline.sag
            for grid in pipeline._grids.values():
                shared[id(grid)] = grid
            self._r_pipeline = copy.deepcopy(pipeline, shared)
            # deepcopy hands back functions unchanged: a stateful plain function (or a
            # closure) would then see the rehearsal's sample; rehearse only true copies
            r_controls = copy.deepcopy(controls_from_raw)
            r_orientation = copy.deepcopy(orientation)
            self._r_controls = None if r_controls is controls_from_raw else r_controls
            self._r_orientation = None if r_orientation is orientation else r_orientation
            self._r_out = np.zeros(len(pipeline.expander.controls))

    def prepare(self) -> None:
        """Collect the garbage and freeze the start-up heap. Call it before torque goes
        on: collecting a large heap (a plot drawn earlier in the process left 90,000
        objects) paused 100 ms, longer than the servos' Bus Watchdog. Afterwards
        collections mid-run are short: the start-up heap (numpy, scipy, the map and
        grid) sits in the permanent generation and only what the run allocates is
        walked. :meth:`run` calls it if nobody did."""
        gc.collect()
        gc.freeze()
        self._prepared = True

    # -- control from outside (signal handlers, UI) --------------------------------------------
    def request_stop(self, reason: str = "stop requested") -> None:
        """Ease to the relaxed pose, then end the run. A second request ends it at once."""
        self._stop_requests += 1
        if self._stop_requests == 1:
            self.stats.stop_reason = self.stats.stop_reason or reason
            self._start_relax(Mode.STOPPING, reason)
        else:
            self.stats.stop_reason = f"{reason} (immediate)"

    # -- internals -------------------------------------------------------------------------
    def _event(self, text: str) -> None:
        self.stats.events.append(text)
        self.log(text)

    def _start_relax(self, mode: Mode, reason: str) -> None:
        if self.mode is Mode.STOPPING:
            return
        if self.mode in (Mode.RUNNING, Mode.WAITING):
            if mode is Mode.RELAXING:
                self.stats.relax_events += 1  # the glove was lost (not a planned stop)
            self._blend_t0 = None  # the easing starts on the next cycle (_relax_targets)
        self.mode = mode
        self._event(f"{reason}: easing to the relaxed pose over {self.relax_time_s:.2f} s")

    def _relax_targets(self, now: float, dt: float) -> tuple[FloatArray, bool]:
        relaxed = self.pipeline.relaxed_pose(*self._orientation)
        np.clip(relaxed, self.pipeline.pose_low, self.pipeline.pose_high, out=relaxed)
        goal = relaxed[self.pipeline.servo_index]
        if self._blend_t0 is None:  # first easing cycle: from what the servos were last sent
            self._blend_t0 = now
            self._blend_from[:] = self._sent
            self._pose_from[:] = self.pipeline.pose if self._accounted else relaxed
        a = min(1.0, (now - self._blend_t0) / self.relax_time_s)
        s = a * a * (3.0 - 2.0 * a)  # smoothstep: no jerk at either end
        self._blend = s
        self.pipeline.targets[:] = self._blend_from + s * (goal - self._blend_from)
        np.clip(self.pipeline.targets, self.pipeline.servo_low, self.pipeline.servo_high,
                out=self.pipeline.targets)
        return self.pipeline.targets, a >= 1.0

    def _rehearse(self, now: float) -> None:
        """The critical path once on scratch state: no effect on the rig, glove or bus."""
        sample = self._last_sample
        if sample is None:
            return
        rehearse_glove = getattr(self.glove, "rehearse", None)
        if rehearse_glove is not None:
            rehearse_glove()
        if self._r_controls is not None:
            self._r_controls(sample.raw, now, self._r_out)
        orientation = (self._r_orientation(sample) if self._r_orientation is not None
                       else self._orientation)
        targets = self._r_pipeline.servo_targets(self._r_out, *orientation, self.period_s)
        rehearse_write = getattr(self.bus, "rehearse_write", None)
        if rehearse_write is not None:
            rehearse_write(targets)

    def _track(self, state: Any, goals: FloatArray) -> None:
        self.stats.reads += 1
        positions = getattr(state, "positions_deg", None)
        stale = getattr(state, "stale", None)
        if positions is None:
            return
        fresh = ~np.asarray(stale, dtype=bool) if stale is not None else np.ones(len(goals), bool)
        if not fresh.all():
            self.stats.stale_reads += 1
        if fresh.any():
            err = np.asarray(positions)[fresh] - goals[fresh]
            self.stats.tracking_sq_sum += float(np.dot(err, err))
            self.stats.tracking_n += int(fresh.sum())
            self.stats.tracking_max_deg = max(self.stats.tracking_max_deg,
                                              float(np.abs(err).max()))

    # -- the loop --------------------------------------------------------------------------
    def _seed(self) -> None:
        """Start from where the servos are: the goals the bus holds them at, else a read."""
        held = getattr(self.bus, "last_goals_deg", None)
        if held is not None and np.all(np.isfinite(held)):
            self.pipeline.seed(np.asarray(held, dtype=np.float64))
        elif not self.pipeline.has_targets:
            state = self.bus.read_state()
            positions = np.asarray(getattr(state, "positions_deg", []), dtype=np.float64)
            stale = np.asarray(getattr(state, "stale", []), dtype=bool)
            if positions.shape == (len(self._sent),) and not stale.any() and np.all(
                    np.isfinite(positions)):
                self.pipeline.seed(positions)
            else:
                raise DeviceError(
                    "cannot start the loop: the servos' present positions are unknown "
                    "(a read came back stale); check the bus, then start again")
        self._sent[:] = self.pipeline.targets

    def run(self, frames: int | None = None, duration_s: float | None = None) -> RunStats:
        """Run ``frames`` cycles or ``duration_s`` seconds (counted from the start, waiting
        for the glove included), then ease to the relaxed pose and return; an e-stop or a
        stop request eases and returns early.

        Until the first glove frame the servos hold where they are; no frame within
        ``glove_timeout_s`` eases them to the relaxed pose.
        """
        stats = self.stats
        clock = self.clock
        period = self.period_s
        try:
            self._seed()
        except DeviceError as exc:
            stats.stop_reason = f"device error: {exc}"
            self._event(f"not starting: {exc}")
            raise
        if not self._prepared:
            self.prepare()
        t0 = clock.now()
        self.started_at = t0
        last_good = t0
        last_cycle = t0
        k = 0
        try:
            while True:
                if self._stop_requests > 1:
                    break
                if self.mode is not Mode.STOPPING:
                    if frames is not None and stats.frames >= frames:
                        stats.stop_reason = f"{frames} frames done"
                        self._start_relax(Mode.STOPPING, f"{frames} frames done")
                    elif duration_s is not None and clock.now() - t0 >= duration_s:
                        stats.stop_reason = f"{duration_s:g} s done"
                        self._start_relax(Mode.STOPPING, f"{duration_s:g} s done")
                deadline = t0 + k * period
                if (self.warm_s > 0 and self._last_sample is not None
                        and clock.now() < deadline - self.warm_s):
                    clock.sleep_until(deadline - self.warm_s)
                    self._rehearse(clock.now())
                clock.sleep_until(deadline)
                now = clock.now()
                late = now - deadline
                if late > period:
                    stats.overruns += 1
                    stats.overrun_max_s = max(stats.overrun_max_s, late)
                    skipped = int(late / period)
                    stats.missed_cycles += skipped
                    k += skipped
                    deadline = t0 + k * period  # this cycle's slot, for the read's deadline
                if stats.frames:
                    stats.periods_s.append(now - last_cycle)
                last_cycle = now
                dt = period

                sample = self.glove.latest()
                t_read = clock.now() if self.profile else 0.0
                if sample is not None:
                    last_good = now
                    stats.glove_samples += 1
                    self._last_sample = sample
                    if getattr(sample, "estop", False) and self.mode is not Mode.STOPPING:
                        stats.estop = True
                        stats.stop_reason = "e-stop"
                        self._start_relax(Mode.STOPPING, "e-stop pressed on the glove")
                    self.controls_from_raw(sample.raw, now, self._controls)
                    t_controls = clock.now() if self.profile else 0.0
                    self._orientation = self.orientation(sample)
                    t_orientation = clock.now() if self.profile else 0.0
                    if self.mode is Mode.WAITING:
                        self.mode = Mode.RUNNING
                    elif self.mode is Mode.RELAXING:
                        self.mode = Mode.RUNNING
                        self._event("glove is back: following it again")
                elif (self.mode in (Mode.RUNNING, Mode.WAITING)
                      and now - last_good > self.glove_timeout_s):
                    what = ("no glove frame yet" if self.mode is Mode.WAITING
                            else "glove silent or garbled")
                    self._start_relax(Mode.RELAXING, f"{what} for {now - last_good:.2f} s")

                done = False
                # one mode for the whole cycle: a signal may call request_stop any time
                mode = self.mode
                if mode is Mode.RUNNING:
                    goals = self.pipeline.servo_targets(self._controls, *self._orientation, dt)
                    t_targets = clock.now() if self.profile else 0.0
                elif mode is Mode.WAITING:
                    goals = self.pipeline.targets  # hold: keeps the watchdog fed
                else:
                    goals, done = self._relax_targets(now, dt)
                stats.bus_clamps += int(self.bus.write_goals_deg(goals))
                if sample is not None:
                    t_write = clock.now()
                    stats.latencies_s.append(t_write - sample.host_time_s)
                    if self.profile and mode is Mode.RUNNING:
                        self.stage_times.append((sample.host_time_s, t_read, t_controls,
                                                 t_orientation, t_targets, t_write))
                # after the write: the full pose for outputs, and the counters
                if mode is Mode.RUNNING:
                    pose: FloatArray | None = self.pipeline.account(
                        self._controls, *self._orientation)
                    self._accounted = True
                elif mode is Mode.WAITING:
                    pose = None
                else:
                    relaxed = self.pipeline.relaxed  # computed by _relax_targets
                    np.multiply(self._pose_from, 1.0 - self._blend, out=self._out_pose)
                    self._out_pose += self._blend * relaxed
                    pose = self._out_pose
                if pose is not None:
                    for out in self.outputs:
                        out(now - t0, pose)
                if k % self.read_every == 0:
                    # a read (and its retries) must leave the next cycle its time
                    state = self.bus.read_state(deadline + period - 0.0003)
                    self.last_state = state
                    self._track(state, self._sent)
                self._sent[:] = goals
                stats.frames += 1
                k += 1
                if done and mode is Mode.STOPPING:
                    stats.stop_reason = stats.stop_reason or "stop requested"
                    break
        except DeviceError as exc:
            stats.stop_reason = f"device error: {exc}"
            self._event(f"stopping: {exc}")
            raise
        finally:
            gc.unfreeze()
            self._prepared = False
            stats.duration_s = clock.now() - t0
            stats.clamps = self.pipeline.clamps
            stats.servo_clamps = self.pipeline.servo_clamps
            stats.nonfinite = self.pipeline.rejected
            stats.slewed = self.pipeline.slewed
        return stats
