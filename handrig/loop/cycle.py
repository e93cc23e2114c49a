"""One cycle of the loop: a glove sample -> servo goals -> Sync Write -> outputs -> read.

The critical path, from taking the newest glove sample to handing the Sync Write
to the OS, is kept short: controls, forearm angles, the mode for the cycle, the
servo step (or an easing), the write. Everything else (latency, the full pose for
the outputs and the counters behind it, the outputs, the state read) comes after
the write. About every ``read_every`` cycles the servos' present state is read
back, when and with the deadline the trigger allows
(:meth:`~handrig.loop.trigger.Trigger.read_deadline`), so that the next cycle
keeps its time; a read after which the next write had to wait is counted.
Between those reads the bus may do its housekeeping reads (watchdogs,
temperatures) in the same way. A tick that catches up (``Tick.catch_up``) takes the
oldest frame a newer one overtook instead of the newest, filtered at its place on the
glove's grid; its full pose and outputs wait until the next cycle's write is out, and
it asks no read (the newer frame is waiting).

Latency is measured twice per glove frame: end to end, from the frame's
``host_time_s`` (its arrival) to the Sync Write handed to the OS, and the compute
part of it, from the cycle's start to the same point.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from handrig.config.rig import READ_PARTS_MAX
from handrig.errors import DeviceError
from handrig.loop.easing import Easing
from handrig.loop.heat import HeatWatch
from handrig.loop.layers import LayerMixer
from handrig.loop.modes import Mode, ModeMachine
from handrig.loop.ports import (
    FloatArray,
    GloveSample,
    ServoBus,
    ServoState,
)
from handrig.loop.settings import LoopParts, RigSettings
from handrig.loop.silence import SilenceWatch
from handrig.loop.stats import RunStats
from handrig.loop.telemetry import CycleView
from handrig.loop.trigger import READ_MARGIN_S, GloveTrigger, Tick, Trigger
from handrig.pose.pipeline import POSE_SIZE

__all__ = ["READ_MARGIN_S", "Cycle"]
READ_SMOOTHING = 0.2  # weight of the newest read's duration in the expected read time
SKIP_GROWTH = 1.25  # a read the bus skipped: the next one needs this much more room


class Cycle:
    """The work of one tick, on the parts it is given (nothing here opens a device),
    at the ``trigger``'s ticks, with the ``settings``' read schedule, easing times and
    silence and heat tiers; ``machine`` says what the puppet does, ``stats`` counts.

    ``latest``, ``controls_from_raw``, ``orientation``, ``targets`` and ``write`` are
    the stage callables, attributes so that a profile can wrap them
    (:class:`handrig.loop.profile.StageProfile`).
    """

    def __init__(self, parts: LoopParts, settings: RigSettings, machine: ModeMachine,
                 stats: RunStats, trigger: Trigger, *,
                 outputs: Sequence[Callable[[float, FloatArray], None]] = ()) -> None:
        glove, bus, pipeline, clock = parts.glove, parts.bus, parts.pipeline, parts.clock
        loop = settings.loop
        period_s = trigger.period_s
        self.bus = bus
        # each read asks one part of the servos in turn (1: every servo at once)
        self.read_parts = max(1, min(settings.read_parts, len(pipeline.servo_joints)))
        self._part = 0
        self.trigger: Trigger = trigger
        self.read_s = 0.0  # expected duration of a present-state read (moving average)
        self._reads_due = 0  # cycles since the last read
        self.read_wire_s = self._wire_floor(
            bus, -(-len(pipeline.servo_joints) // self.read_parts))
        self.pipeline = pipeline
        self.clock = clock
        self.machine = machine
        self.stats = stats
        self.period_s = period_s
        self.read_every = settings.read_every
        self.outputs = tuple(outputs)
        # a glove trigger pumps the port itself: the cycle then takes the newest sample
        # without reading the port again
        self.glove = glove
        self.latest: Callable[[], GloveSample | None] = (
            glove.take if isinstance(self.trigger, GloveTrigger) else glove.latest)
        self.controls_from_raw: Callable[..., Any] = parts.controls_from_raw
        self.orientation: Callable[[GloveSample], tuple[float, float]] = parts.orientation
        self.targets: Callable[..., FloatArray] = pipeline.servo_targets
        self.write: Callable[[FloatArray], int] = bus.write_goals_deg
        # what the bus holds, as the loop's goals (with gravity: before its offsets)
        self._loop_goals: Callable[[FloatArray], FloatArray] = lambda held: held
        if parts.gravity is not None:  # what the bus gets: the goals held up against gravity
            write, compensate = bus.write_goals_deg, parts.gravity.apply
            self.write = lambda goals: write(compensate(goals, *self.angles))
            self._loop_goals = parts.gravity.loop_goals
        # takes layered under the glove (handrig.loop.layers), handed in from any thread
        self.layers = LayerMixer(pipeline)
        # port events of the glove, silence events of the bus: into the run's events
        self._drains: tuple[Callable[[], list[str]], ...] = (
            glove.drain_events, bus.drain_events, lambda: self.silence.drain_events(),
            lambda: self.heat.drain_events(), self.layers.drain_events)
        # the bus's upkeep (watchdogs, temperatures), midway between state reads
        self.housekeeping: Callable[[float], bool] = bus.housekeeping
        self._housekeeping_slot = self.read_every // 2 if self.read_every > 1 else -1
        n = len(pipeline.servo_joints)
        self.relax = Easing(n, POSE_SIZE, loop.relax_time_s)
        self.resume = Easing(n, POSE_SIZE, loop.resume_time_s)
        self.controls = np.zeros(len(pipeline.expander.controls))
        self.angles: tuple[float, float] = (0.0, 0.0)  # forearm (inclination, rotation)
        self.sent = np.zeros(n)  # the goals last written
        self._step = np.zeros(n)
        self._slew_deg_s = pipeline.slew_deg_s
        # the [silence] tiers for servos that stop answering: decided here, from the reads
        self.silence = SilenceWatch(bus, settings.silence, pipeline.slew_deg_s,
                                    loop_goals=self._loop_goals)
        # the [heat] tiers for servos that warm up: decided here, from the temperatures read
        self.heat = HeatWatch(bus, settings.heat)
        self.sample: GloveSample | None = None  # the newest glove sample
        self._filtered_s = float("-inf")  # the filter time of the last frame given it
        self.last_state: ServoState | None = None  # the newest ServoState read back
        self.t0_s = 0.0
        self._pose: FloatArray | None = None  # the full pose last output
        # a caught-up frame's full pose waits until the newest frame's write is out
        self._deferred_controls = np.zeros_like(self.controls)
        self._deferred: tuple[float, tuple[float, float]] | None = None  # (t_s, angles)

    @property
    def last_pose(self) -> FloatArray | None:
        """The full pose last output (None before the first)."""
        return self._pose

    def view(self) -> CycleView:
        """What the cycle holds now, for a telemetry snapshot (the live arrays: the
        snapshot copies them on the loop's thread)."""
        sample = self.sample
        return CycleView(
            controls=self.controls, raw=None if sample is None else sample.raw,
            angles_deg=self.angles, pose=self._pose, goals_deg=self.sent, state=self.last_state,
            frame_s=math.nan if sample is None else sample.host_time_s,
            layers=self.layers.status)

    def rehearse(self) -> None:
        """The next frame's path once on scratch data, changing nothing the loop reads
        (the trigger's warm-up, :class:`~handrig.loop.trigger.GloveTrigger`): the glove
        decodes its last bytes again, the pipeline's compiled step and the bus's goal
        write are built into scratch and dropped. Nothing before the first frame."""
        if self.sample is None:
            return
        self.glove.rehearse()
        self.bus.rehearse_write(self.pipeline.rehearse(self.controls, *self.angles))

    def seed(self) -> None:
        """Start from where the servos are: the goals the bus holds them at, else a read.
        DeviceError when neither is known (the loop must not start blind)."""
        held = self._loop_goals(np.asarray(self.bus.last_goals_deg, dtype=np.float64))
        pipeline = self.pipeline
        known = np.isfinite(held)
        if held.shape == (len(self.sent),) and known.all():
            pipeline.seed(held)
        elif held.shape == (len(self.sent),) and known.any():
            # the bus holds the others: a servo it never sends a goal (left out at
            # start-up) is seeded at 0, its goal is never written
            pipeline.seed(np.where(known, held, 0.0))
        elif not pipeline.has_targets:
            state = self.bus.read_state()
            positions = np.asarray(state.positions_deg, dtype=np.float64)
            stale = np.asarray(state.stale, dtype=bool)
            if positions.shape == (len(self.sent),) and not stale.any() and np.all(
                    np.isfinite(positions)):
                pipeline.seed(positions)
            else:
                raise DeviceError(
                    "cannot start the loop: the servos' present positions are unknown "
                    "(a read came back stale); check the bus, then start again")
        self.sent[:] = pipeline.targets

    def run(self, tick: Tick) -> bool:
        """One cycle at ``tick``; True when the run is over (the stop's easing is done)."""
        now = tick.now_s
        machine = self.machine
        sample, t_sample = None, now
        if tick.catch_up:  # the frame behind the newest (see Tick.catch_up)
            sample = self.glove.take_behind()
            if sample is not None:  # its filter time: a period per frame before the newest,
                newest = self.glove.peek()  # and never back before the frame filtered last
                behind = max(1, (0 if newest is None else newest.count) - sample.count)
                t_sample = now - behind * tick.behind_s
                last = self._filtered_s  # a backlog that came in a bunch: spread up to now
                if t_sample <= last:
                    t_sample = last + (now - last) / (behind + 1)
                self.stats.frames_caught_up += 1
        if sample is None:
            sample = self.latest()
        layers = self.layers
        layers.advance(now)
        if sample is not None:
            self._filtered_s = t_sample
            self.controls_from_raw(sample.raw, t_sample, self.controls)
            self.angles = self.orientation(sample)
            mode = machine.frame(now, sample.estop)
        else:
            mode = machine.silence(now)
        done = False
        if mode is Mode.RUNNING:
            goals = self.targets(self.controls, *self.angles, tick.dt_s)
            if layers.active:  # blended before the slew limit, slewed from the goals sent
                layers.mix_goals(self.pipeline.raw_targets, self.sent, goals,
                                 self._slew_deg_s * max(tick.dt_s, 0.0))
        elif mode is Mode.WAITING:
            goals = self.sent  # hold: keeps the watchdog fed
        elif mode is Mode.RESUMING:
            goals, done = self._resume_goals(now, tick.dt_s)
        else:
            relaxed = self.pipeline.relaxed_targets(*self.angles)
            goals, done = self.relax.goals(now, self.sent, self._pose, relaxed)
        if self.silence.steering:  # servos held for silence, or coming back from it
            goals = self.silence.steer(goals, self.sent, tick.dt_s)
        bus_clamps = self.write(goals)
        self._after_write(tick, sample, mode, goals, bus_clamps)
        if done:
            if mode is Mode.RESUMING:
                machine.resumed()
            elif mode is Mode.STOPPING:
                return True
        return False

    def _resume_goals(self, now: float, dt_s: float) -> tuple[FloatArray, bool]:
        """Easing from where the servos are to the glove's targets before the slew limit,
        then the slew limit on the eased step: at the end of the easing the goals are the
        pipeline's own slew-limited step, and following the glove takes over seamlessly."""
        pipeline, sent = self.pipeline, self.sent
        pipeline.seed(sent)  # the slew limit counts from what the servos were sent
        self.targets(self.controls, *self.angles, dt_s)
        self.layers.mix_targets(pipeline.raw_targets)
        goals, done = self.resume.goals(now, sent, self._pose, pipeline.raw_targets)
        step = self._step
        max_step = self._slew_deg_s * dt_s
        np.subtract(goals, sent, out=step)
        np.clip(step, -max_step, max_step, out=step)
        np.add(sent, step, out=goals)
        return goals, done

    def _after_write(self, tick: Tick, sample: GloveSample | None, mode: Mode,
                     goals: FloatArray, bus_clamps: int) -> None:
        stats = self.stats
        written = self.clock.now()
        handed = self.bus.last_write_s  # the Sync Write's os.write returned (NaN: unknown)
        if tick.now_s <= handed <= written:
            written = handed
        stats.bus_clamps += int(bus_clamps)
        if sample is not None:
            latency = written - sample.host_time_s
            stats.latency.add(latency)
            stats.compute.add(written - tick.now_s)
            stats.latencies_s.append(latency)
            stats.glove_samples += 1
            count, before = sample.count, 0 if self.sample is None else self.sample.count
            # frames the glove sent back to back, superseded on arrival (not by a busy loop)
            bursts = self.trigger.take_bursts()
            stalled = self.trigger.take_stalled()  # the host's backlog, not the glove's
            if before and count > before + 1:
                superseded = count - before - 1
                bursts = min(superseded, bursts)
                stalled = min(superseded - bursts, stalled)
                stats.frames_in_bursts += bursts
                stats.frames_in_host_stalls += stalled
                stats.frames_skipped += superseded - bursts - stalled
            self.sample = sample
        else:
            stats.cycles_without_frame += 1
        pipeline = self.pipeline
        t_s = tick.now_s - self.t0_s
        if self._deferred is not None:  # the caught-up frame before this one, in order
            (t_before, angles), self._deferred = self._deferred, None
            caught = pipeline.account(self._deferred_controls, *angles, slewed=False)
            self.layers.mix_pose(caught, self.t0_s + t_before)  # the take at its time
            self._output(t_before, caught)
        pose: FloatArray | None
        if mode is Mode.RUNNING and tick.catch_up:
            # the newest frame is waiting: its write first, this one's full pose after it
            pipeline.count_slewed()
            self._deferred_controls[:] = self.controls
            self._deferred = (t_s, self.angles)
            pose = None
        elif mode is Mode.RUNNING:
            pose = self._layered(pipeline.account(self.controls, *self.angles))
        elif mode is Mode.WAITING:
            pose = None
        elif mode is Mode.RESUMING:
            pose = self.resume.pose(self._layered(pipeline.account(self.controls,
                                                                   *self.angles)))
        else:
            pose = self.relax.pose(pipeline.relaxed)  # clamped by relaxed_targets
        if pose is not None:
            self._output(t_s, pose)
        if tick.catch_up:  # no read: the newest frame is waiting
            self._reads_due += 1
        else:
            self._read(tick)
        self.sent[:] = goals
        if mode is not Mode.RUNNING and mode is not Mode.WAITING:
            pipeline.seed(goals)  # the pipeline's targets stay what the servos were sent
        stats.frames += 1

    def _layered(self, pose: FloatArray) -> FloatArray:
        """The full pose with the layers playing blended in (what the servos get)."""
        self.layers.mix_pose(pose)
        return pose

    def _output(self, t_s: float, pose: FloatArray) -> None:
        self._pose = pose
        for out in self.outputs:
            out(t_s, pose)

    def claim_events(self) -> None:
        """From here on what the glove and the bus say is the run's events (the loop takes
        them after each read), not only lines in the log: a part says a thing to the log
        alone while nobody has drained its events, and a hardware error found by the
        start-up read or the run's first read would be missing from the run's events."""
        for drain in self._drains:
            for text in drain():
                self.machine.event(text)

    def _take_events(self) -> None:
        machine = self.machine
        for drain in self._drains:
            for text in drain():
                machine.event(text)
        machine.servos_silent(self.silence.relax_reason or self.heat.relax_reason)

    @staticmethod
    def _wire_floor(bus: ServoBus, n: int) -> float:
        """The least a read right after a write can take: the write's goal Sync Write
        still on the wire, then the read's request and replies (0 for a bus that has no
        serial wire)."""
        return bus.read_wire_s(n) + bus.write_wire_s()

    def _split_reads(self) -> None:
        """A forced read whose wire time (the goals' write still on the wire, then the
        read) is more than the gap from the cycle's start to the next frame delays that
        frame's write by the read's length, and no gap will ever fit it: from now on
        each read asks half as many servos (at most ``READ_PARTS_MAX`` parts), so it is
        shorter and may fit. Said once per split; each servo is then read less often.
        A host that came late, or a line that must go quiet, does not split reads."""
        n = len(self.pipeline.servo_joints)
        most = min(READ_PARTS_MAX, n)
        if self.read_parts >= most:
            return
        before = -(-n // self.read_parts)
        self.read_parts = min(most, 2 * self.read_parts)
        self._part %= self.read_parts
        each = -(-n // self.read_parts)
        self.read_wire_s = self._wire_floor(self.bus, each)
        self.read_s = 0.0  # what reads took was the longer reads' time
        self.stats.read_splits += 1
        self.machine.event(
            f"reads of {before} servos found no room between the glove's frames (each "
            f"one delayed a write): each read now asks {each} servos, in "
            f"{self.read_parts} parts")

    def _read(self, tick: Tick) -> None:
        """The present-state read, if the trigger finds room for one in this cycle."""
        self._reads_due += 1
        trigger, clock = self.trigger, self.clock
        start = clock.now()
        read_s = max(self.read_s, self.read_wire_s)
        read_s += self.bus.quiet_wait_s()  # a failed reply's quiet line, before the request
        deadline = trigger.read_deadline(tick, start, self._reads_due, self.read_every, read_s)
        if deadline is None:
            if self._reads_due == self._housekeeping_slot:
                self.housekeeping(tick.next_s - READ_MARGIN_S)
            return
        due, self._reads_due = self._reads_due, 0
        if deadline > tick.next_s and self.read_wire_s > tick.next_s - tick.now_s - READ_MARGIN_S:
            self._split_reads()  # forced, and the wire alone needs more than the gap
        parts = self.read_parts
        silence = self.silence
        silence.note_read(start, late=deadline <= start)
        state = (self.bus.read_state(deadline, (self._part, parts)) if parts > 1
                 else self.bus.read_state(deadline))
        end = clock.now()
        if (silence.active or silence.waiting or not state.all_fresh
                or silence.rebooted(state)):
            silence.update(state, end)  # DeviceTimeoutError when the action is "stop"
        if not state.sent:
            # the bus found no room for it after all (a line to let go quiet, replies
            # slower than the wire): still due, so a forced read comes in time, and the
            # next one is asked only with more room than this one had
            self._reads_due = due
            self.read_s = max(self.read_s, SKIP_GROWTH * (deadline - start))
            self._take_events()
            return
        self._part = (self._part + 1) % parts
        took = end - start
        self.read_s = took if not self.read_s else self.read_s + READ_SMOOTHING * (
            took - self.read_s)
        if trigger.delayed(tick, end):
            self.stats.writes_delayed += 1
        self.last_state = state
        heat = self.heat
        heat.update(state)  # ServoFault when a servo is too hot and the action is "stop"
        while heat.uncapped:  # full effort back: from where its joint gave way
            i = heat.uncapped.pop()
            if np.isfinite(state.positions_deg[i]):
                self.silence.ease_from(i, float(state.positions_deg[i]))
        self._track(state, self.sent)
        self._take_events()

    def _track(self, state: ServoState, goals: FloatArray) -> None:
        stats = self.stats
        stats.reads += 1
        positions = state.positions_deg
        fresh = ~np.asarray(state.stale, dtype=bool)
        asked = state.asked
        if asked is not None:  # a read of a part: the others' readings are older
            asked = np.asarray(asked, dtype=bool)
            fresh &= asked
            if not fresh[asked].all():
                stats.stale_reads += 1
        elif not fresh.all():
            stats.stale_reads += 1
        if fresh.any():
            err = np.asarray(positions)[fresh] - goals[fresh]
            stats.tracking_sq_sum += float(np.dot(err, err))
            stats.tracking_n += int(fresh.sum())
            stats.tracking_max_deg = max(stats.tracking_max_deg, float(np.abs(err).max()))
