"""The live rig: the realtime loop from glove to servos, with its safety behaviour.

``Rig(parts, settings)`` runs cycles on the parts it is given
(:class:`~handrig.loop.settings.LoopParts`: the glove, the bus, the pipeline, the
injected :class:`~handrig.clock.Clock`) with the settings of
:class:`~handrig.loop.settings.RigSettings`: at ``rate_hz`` (``[loop] mode =
"fixed"``), or one per glove frame as it arrives, between ``floor_hz`` and
``ceiling_hz`` (``mode = "glove"``). Each cycle it takes the newest glove sample without
blocking, turns it into servo targets through the
:class:`~handrig.pose.pipeline.PosePipeline`, hands one Sync Write to the bus, and
every ``read_every`` cycles reads the servos' present state back.

The loop is made of parts (:mod:`handrig.loop`): a trigger says when a cycle runs
(:class:`~handrig.loop.trigger.FixedRateTrigger`,
:class:`~handrig.loop.trigger.GloveTrigger`), the mode machine what the
puppet does (:mod:`handrig.loop.modes`), the cycle does one cycle's work
(:mod:`handrig.loop.cycle`) with two easings (:mod:`handrig.loop.easing`), and the
statistics are fixed-size (:mod:`handrig.loop.stats`). :class:`Rig` puts them
together.

Safety (what a puppeteer relies on during a show):

* glove silent or garbled for longer than ``glove_timeout_s``: the puppet eases
  to the relaxed pose over ``relax_time_s`` and the rig says so; after
  ``resume_frames`` good frames in a row it eases back to the glove's pose over
  ``resume_time_s``;
* the glove's e-stop button or a stop request (a signal, the UI): ease to the
  relaxed pose, then stop (the bus's torque context then disables torque); a
  second request stops at once;
* the relax key (:meth:`Rig.toggle_relax`): ease to relaxed and hold there until
  it is pressed again; the e-stop key (:meth:`Rig.estop`): end at the next cycle
  with no easing, so torque goes off at once;
* a lost servo port: stop cleanly with the device's message;
* nothing outside the limits: the pipeline clamps to joint and servo limits, and
  the bus clamps again to each servo's configured range.
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

from handrig.clock import Clock
from handrig.config.rig import RigConfig
from handrig.errors import DeviceError
from handrig.loop.cycle import Cycle
from handrig.loop.modes import Mode, ModeMachine
from handrig.loop.ports import (
    ControlsFromRaw,
    FloatArray,
    GloveSource,
    OrientationLike,
    ServoBus,
)
from handrig.loop.profile import StageProfile
from handrig.loop.settings import LoopParts, RigSettings
from handrig.loop.stats import RunStats
from handrig.loop.telemetry import SnapshotBuilder, Telemetry
from handrig.loop.trigger import FixedRateTrigger, GloveTrigger, Tick, Trigger
from handrig.pose.gravity import GravityCompensation
from handrig.pose.pipeline import PosePipeline
from handrig.realtime import CpuWake

__all__ = ["ControlsFromRaw", "GloveSource", "LoopParts", "Mode", "OrientationLike", "Rig",
           "RigSettings", "RunStats", "ServoBus"]

WIRE_SHARE = 0.9  # goal writes may fill at most this share of the wire
PUBLISH_ROOM_S = 0.001  # a telemetry snapshot (~0.2 ms) is built only with this much room


class Rig:
    """The realtime loop. Dependencies are passed in (``parts``); nothing here opens a
    device. ``settings`` default to the config's (:class:`RigSettings`);
    :meth:`from_config` builds a rig from a rig file's settings.

    ``trigger``: what starts each cycle (default: by ``settings.loop.mode``, a
    :class:`FixedRateTrigger` at ``rate_hz`` or a :class:`GloveTrigger` between
    ``floor_hz`` and ``ceiling_hz``; either stamps the glove's frames as they arrive).
    ``outputs`` are called after each write with (seconds since the start, the full
    pose); ``log`` gets the run's events as lines.
    """

    @classmethod
    def from_config(
        cls, config: RigConfig, glove: GloveSource, bus: ServoBus, pipeline: PosePipeline,
        clock: Clock, *, controls_from_raw: ControlsFromRaw, orientation: OrientationLike,
        outputs: Sequence[Callable[[float, FloatArray], None]] = (),
        log: Callable[[str], None] = print, profile: bool = False, ease_in: bool = False,
        raw_channels: Sequence[int] = (), gravity: GravityCompensation | None = None,
    ) -> Rig:
        """The loop with the rig file's rates and safety timings (``[loop]``, ``[bus]``).
        In loop mode "glove" the ceiling is also held below the rate at which goal Sync
        Writes fill the wire (``0.9 / wire time``), so writes never queue on the bus."""
        settings = RigSettings.from_config(config, ease_in=ease_in, profile=profile)
        loop = config.loop
        write_s = bus.write_wire_s()
        if write_s > 0.0:
            ceiling_hz = max(loop.floor_hz, min(loop.ceiling_hz, WIRE_SHARE / write_s))
            settings = replace(settings, loop=replace(loop, ceiling_hz=ceiling_hz))
        parts = LoopParts(glove, bus, pipeline, clock, controls_from_raw=controls_from_raw,
                          orientation=orientation,
                          raw_channels=tuple(int(i) for i in raw_channels), gravity=gravity)
        return cls(parts, settings, outputs=outputs, log=log)

    def __init__(
        self,
        parts: LoopParts,
        settings: RigSettings | None = None,
        *,
        outputs: Sequence[Callable[[float, FloatArray], None]] = (),
        log: Callable[[str], None] = print,
        trigger: Trigger | None = None,
    ) -> None:
        settings = settings if settings is not None else RigSettings()
        self.parts = parts
        self.settings = settings
        glove, clock, loop = parts.glove, parts.clock, settings.loop
        self.glove = glove
        self.bus = parts.bus
        self.pipeline = parts.pipeline
        self.clock = clock
        if trigger is None:
            if loop.mode == "glove":
                trigger = GloveTrigger(clock, glove, floor_hz=loop.floor_hz,
                                       ceiling_hz=loop.ceiling_hz, catch_up=loop.catch_up,
                                       poll_s=loop.glove_poll_us * 1e-6,
                                       warm_up_s=loop.warm_up_us * 1e-6)
            elif loop.mode == "fixed":
                trigger = FixedRateTrigger(clock, loop.rate_hz, glove=glove)
            else:
                raise ValueError(f"loop mode {loop.mode!r} unknown: use 'fixed' or 'glove'")
        self.trigger = trigger
        self.period_s = self.trigger.period_s
        self.glove_timeout_s = loop.glove_timeout_s
        self.relax_time_s = loop.relax_time_s
        self.log = log
        self.stats = RunStats(loop_mode="glove" if isinstance(self.trigger, GloveTrigger)
                              else "fixed")
        self.started_at = 0.0
        self._prepared = False  # prepare() ran: garbage collected, start-up heap frozen
        self.machine = ModeMachine(
            glove_timeout_s=loop.glove_timeout_s, relax_time_s=loop.relax_time_s,
            resume_frames=loop.resume_frames, resume_time_s=loop.resume_time_s,
            event=self._event, stats=self.stats, ease_in=settings.ease_in,
        )
        self.cycle = Cycle(parts, settings, self.machine, self.stats, self.trigger,
                           outputs=outputs)
        if isinstance(self.trigger, GloveTrigger):  # the warm-up before each expected frame
            self.trigger.warm_up.rehearse_with(self.cycle.rehearse)
        self.machine.on_relax = self.cycle.relax.restart
        self.machine.on_resume = self.cycle.resume.restart
        self.telemetry = Telemetry()
        """The newest :class:`~handrig.loop.telemetry.LoopSnapshot`, for any thread."""
        self._snapshot = SnapshotBuilder(
            parts, self.machine, self.stats, lambda: self.started_at, self.cycle.view,
            lambda: self.cycle.outputs)
        self.stage_profile = StageProfile(clock) if settings.profile else None
        if self.stage_profile is not None:
            self.stage_profile.wrap(self.cycle)

    # -- what callers read or set ------------------------------------------------------------
    @property
    def mode(self) -> Mode:
        return self.machine.mode

    @property
    def last_state(self) -> Any:
        """The newest ServoState read back (None before the first read)."""
        return self.cycle.last_state

    @property
    def outputs(self) -> tuple[Callable[[float, FloatArray], None], ...]:
        """Called after each write with (seconds since the start, the full pose)."""
        return self.cycle.outputs

    @outputs.setter
    def outputs(self, outputs: Sequence[Callable[[float, FloatArray], None]]) -> None:
        self.cycle.outputs = tuple(outputs)

    def prepare(self) -> None:
        """Collect the garbage and freeze the start-up heap. Call it before torque goes
        on: collecting a large heap can pause the process for longer than the servos'
        Bus Watchdog. Afterwards collections mid-run are short: the start-up heap
        (numpy, scipy, the map and grid) sits in the permanent generation and only what
        the run allocates is walked. :meth:`run` calls it if nobody did."""
        gc.collect()
        gc.freeze()
        self._prepared = True

    def keep_awake(self, wake: CpuWake) -> None:
        """Hold ``wake`` (idle CPUs poll) from the warm-up before each expected glove
        frame until its cycle is done (``[loop] keep_cpus_awake``; see
        :class:`~handrig.realtime.CpuWake`)."""
        self.trigger.keep_awake(wake)

    def request_stop(self, reason: str = "stop requested") -> None:
        """Ease to the relaxed pose, then end the run. A second request ends it at once.
        Safe from a signal handler: the loop acts on it between cycles."""
        self.machine.request_stop(reason)

    def toggle_relax(self) -> None:
        """Relax and hold the relaxed pose; called again, follow the glove again (easing
        back in). Safe from another thread (the keys): the loop acts on it between cycles."""
        self.machine.toggle_relax()

    def relax(self, reason: str) -> None:
        """Relax and hold, as :meth:`toggle_relax` when following (a cue); any thread."""
        self.machine.request_relax(reason)

    def resume(self, reason: str) -> None:
        """Follow the glove again, as :meth:`toggle_relax` when held (a cue); any thread."""
        self.machine.request_resume(reason)

    def estop(self, reason: str = "e-stop key") -> None:
        """End the run at the next cycle without easing: the caller's torque context then
        turns torque off at once. Safe from another thread or a signal handler."""
        self.machine.request_estop(reason)

    # -- the loop ------------------------------------------------------------------------------
    def _event(self, text: str) -> None:
        self.stats.events.append(text)
        self.log(text)

    def run(self, frames: int | None = None, duration_s: float | None = None, *,
            done_reason: str = "") -> RunStats:
        """Run ``frames`` cycles or ``duration_s`` seconds (counted from the start, waiting
        for the glove included), then ease to the relaxed pose and return; an e-stop or a
        stop request eases and returns early. ``done_reason``: the stop reason when the
        length is reached (default "N frames done" / "S s done").

        Until the first glove frame the servos hold where they are; no frame within
        ``glove_timeout_s`` eases them to the relaxed pose.
        """
        stats, clock, machine, cycle = self.stats, self.clock, self.machine, self.cycle
        cycle.claim_events()
        try:
            cycle.seed()
        except DeviceError as exc:
            machine.stop_reason = f"device error: {exc}"
            self._event(f"not starting: {exc}")
            raise
        if not self._prepared:
            self.prepare()
        t0 = clock.now()
        self.started_at = t0
        self.trigger.start(t0)
        machine.start(t0)
        cycle.t0_s = t0
        cycle.layers.start(t0)
        tick = Tick()
        cpu0 = time.thread_time()
        last_start: float | None = None
        try:
            while True:
                machine.poll()
                if machine.stop_now:
                    break
                if frames is not None and stats.frames >= frames:
                    machine.finish(done_reason or f"{frames} frames done")
                elif duration_s is not None and clock.now() - t0 >= duration_s:
                    machine.finish(done_reason or f"{duration_s:g} s done")
                self.trigger.wait(tick, settle=False)  # settled by the read schedule
                over = cycle.run(tick)  # at once: the bookkeeping below is off the frame's path
                if tick.skipped:
                    stats.add_overrun(tick.late_s, tick.skipped)
                if last_start is not None:
                    stats.period.add(tick.now_s - last_start)
                last_start = tick.now_s
                # a snapshot only where it delays no frame: not while the newest frame
                # waits (a catch-up tick), and with room before the next one is expected
                if not tick.catch_up and clock.now() + PUBLISH_ROOM_S < tick.next_s:
                    self.telemetry.offer(tick.now_s, self._snapshot)
                if over:
                    machine.stop_reason = machine.stop_reason or "stop requested"
                    break
        except DeviceError as exc:
            machine.stop_reason = f"device error: {exc}"
            self._event(f"stopping: {exc}")
            raise
        finally:
            gc.unfreeze()
            self._prepared = False
            stats.duration_s = clock.now() - t0
            stats.cpu_s = time.thread_time() - cpu0
            stats.ceiling_waits = self.trigger.ceiling_waits
            self._pipeline_figures()
            watch = self.cycle.silence
            stats.servo_silences, stats.servos_held = watch.silences, watch.held
            stats.servo_recoveries = watch.recoveries
            stats.servo_recovery_reads_max = watch.recovery_reads_max
            stats.servos_admitted = watch.admitted
            stats.silence_counts = watch.counts()
            heat = self.cycle.heat
            stats.heat_warnings, stats.heat_reliefs = heat.warnings, heat.reliefs
            stats.heat_actions = heat.actions
            stats.max_temperature_c = tuple(float(t) for t in heat.max_c)
            stats.hottest = heat.hottest()
            self._snapshot.finished = True
            self.telemetry.offer(clock.now(), self._snapshot, force=True)
        return stats

    def _pipeline_figures(self) -> None:
        stats, pipeline = self.stats, self.pipeline
        stats.clamps = pipeline.clamps
        stats.servo_clamps = pipeline.servo_clamps
        stats.nonfinite = pipeline.rejected
        stats.slewed = pipeline.slewed
