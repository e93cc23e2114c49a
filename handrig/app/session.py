"""One live session: devices opened, torque on, the loop run, torque off, figures out.

Shared by ``handrig run`` and ``handrig demo``. The factory (:mod:`handrig.app.factory`)
opens the glove, the servo bus (with its emulator for ``"sim"``) and the outputs
and builds the rig; this module commissions the servos, runs the rig inside the
bus's torque context, and checks afterwards, by reading every servo's Torque
Enable, that torque is off. A session always returns its summary, with the error
in it when there was one.

Every way a user ends a run is handled alike (:class:`ExitSignals`): Ctrl-C
(SIGINT), SIGTERM, SIGHUP (the terminal or the SSH session closed) and SIGQUIT.
Before the rig is ready a signal unwinds (devices closed, emulators stopped,
torque never on). While it runs, the first signal eases to the relaxed pose and
stops, a second stops at the next cycle, a third raises at once (torque still
goes off on the way out). During torque-off and shutdown signals are counted and
ignored. The emulators run in sessions of their own, so a Ctrl-C reaches the rig
alone and they are stopped after torque is off.
"""

from __future__ import annotations

import contextlib
import gc
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from types import FrameType, TracebackType
from typing import Any

import numpy as np

from handrig.app import factory as app
from handrig.app import takes
from handrig.app.factory import RigParts
from handrig.clock import Clock, MonotonicClock
from handrig.devices.glove import GloveSource
from handrig.devices.servo import DynamixelBus
from handrig.devices.servo.registers import Reg
from handrig.errors import DeviceError, HandrigError, SafetyStop
from handrig.loop.stats import RunStats
from handrig.realtime import pinned_loop, realtime_priority

EXIT_SIGNALS: tuple[signal.Signals, ...] = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT")
    if hasattr(signal, name))


@dataclass
class LiveOptions:
    glove: str | None = None  # PORT, opengloves:PORT, replay:FILE (None: glove.toml)
    glove_left: str | None = None  # a two-hand rig's left glove (handrig.app.two_hands)
    bus_left: str | None = None  # a two-hand rig's left bus, with [left_bus] (None: its port)
    show: str = ""  # the show file's name, for the panel (handrig run --show)
    recorded: str = ""  # the recording an emulated glove on ``glove`` streams (handrig demo)
    bus: str | None = None  # PORT or "sim" (None: rig.toml)
    frames: int | None = None
    duration_s: float | None = None
    wire_timing: bool = True  # for the simulated bus
    viewer: bool = False
    vmc: str | None = None
    record: str | None = None
    record_rate_hz: float | None = None  # a BVH take's frame rate (None: the glove's)
    record_glove: str | None = None  # a glove take: what the glove sent (app/takes.py)
    record_glove_left: str | None = None  # a two-hand run's left glove take
    take: Callable[[Clock], GloveSource] | None = None  # handrig play: the take, as the glove
    # the first frame eases in from where the servos rest over [loop] resume_time_s, so a
    # show never starts with a jump (run, demo, play); False: straight to the first goal
    ease_in: bool = True
    done_reason: str = ""  # the stop reason when frames/duration_s is reached ("": "S s done")
    panel: bool = False  # the live panel (plain lines when stdout is no terminal)
    keys: bool = True  # with the panel: read the show keys when stdin is a terminal
    sim_faults: str = ""
    # "sim" buses' emulators already started (handrig demo: their start-ups overlap)
    started: app.StartedEmulators | None = None
    snapshot_every: int = 0  # keep present positions every N frames (for rendering)
    verbose: bool = False  # log every commissioning step
    profile: bool = False  # time the critical path's stages (bench_rig)
    log: Callable[[str], None] = field(default=lambda text: print(text, file=sys.stderr))
    on_rig: Callable[[Any], None] | None = None  # given the rig once built (the --view)
    # a two-hand run (app/two_hands.py) instead: both hands' rigs by hand and the
    # controls that act on both, as the keys do (the --view)
    on_hands: Callable[[Mapping[str, Any], Any], None] | None = None


@dataclass
class LiveResult:
    """``summary``: the figures (:func:`handrig.app.factory.summary_dict`, plus ``error`` when the
    session ended with one); ``started``: whether the rig got as far as torque-on;
    ``snapshots``: present positions kept every ``snapshot_every`` frames, taken at
    ``snapshot_times_s`` (seconds since the loop started)."""

    summary: dict[str, Any]
    snapshots: list[np.ndarray]
    joint_names: tuple[str, ...]
    sim_output: str = ""
    error: HandrigError | None = None
    started: bool = False
    snapshot_times_s: list[float] = field(default_factory=list)  # of each snapshot


READBACK_BUDGET_S = 1.5  # reading Torque Enable back at exit: a silent servo costs 0.4 s


def torque_is_off(bus: DynamixelBus) -> bool | None:
    """Read Torque Enable back from every servo: True if all are off, None if unreadable."""
    return torque_readback(bus)[0]


def torque_readback(bus: DynamixelBus) -> tuple[bool | None, list[str]]:
    """Torque Enable read back from every servo given torque: (True if every one reads
    0, False if one reads 1, None if one could not be read; the servos not confirmed
    off, each named with why). A port that stopped draining is not asked at all, and
    the reads stop at ``READBACK_BUDGET_S`` (the servos not asked are named). A servo
    left out at start-up is asked too, its silence no failure."""
    left_out = set(bus.left_out)
    given = [i for i in range(bus.n_servos) if i not in left_out]
    if bus.port_stalled:
        return None, [f"{bus.describe(i)}: not read back (servo port {bus.port} stopped "
                      "draining)" for i in given]
    unconfirmed: list[str] = []
    on = unread = False
    end = bus.clock.now() + READBACK_BUDGET_S
    for i in range(bus.n_servos):
        if bus.clock.now() >= end:
            if i not in left_out:
                unread = True
                unconfirmed.append(f"{bus.describe(i)}: not read back (the "
                                   f"{READBACK_BUDGET_S:g} s went on the servos before)")
            continue
        try:
            value = bus.read_register(i, Reg.TORQUE_ENABLE)
        except HandrigError as exc:
            if i not in left_out:
                unread = True
                unconfirmed.append(f"{bus.describe(i)}: not read back ({exc})")
            continue
        if value != 0:
            on = True
            unconfirmed.append(f"{bus.describe(i)}: torque still on")
    return (False if on else None if unread else True), unconfirmed


class ExitSignals:
    """SIGINT, SIGTERM, SIGHUP and SIGQUIT, handled alike for one session (main thread
    only; elsewhere nothing is installed). See the module docstring for what each
    phase does with them: :meth:`arm` when the rig can be asked to stop, :meth:`disarm`
    when the loop is over."""

    def __init__(self) -> None:
        self.received = 0
        self.last = ""
        self._stop: Callable[[str], None] | None = None
        self._ignoring = False
        self._while_armed = 0
        self._saved: dict[int, Any] = {}

    def __enter__(self) -> ExitSignals:
        if threading.current_thread() is threading.main_thread():
            for sig in EXIT_SIGNALS:
                self._saved[sig] = signal.signal(sig, self._handler)
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        for sig, old in self._saved.items():
            signal.signal(sig, old)
        self._saved.clear()

    def arm(self, stop: Callable[[str], None]) -> None:
        """From now on a signal calls ``stop(reason)`` (twice at most), then raises."""
        self._stop = stop

    def disarm(self) -> None:
        """The loop is over: torque-off and shutdown must finish; signals are ignored."""
        self._stop = None
        self._ignoring = True

    def _handler(self, signum: int, frame: FrameType | None) -> None:
        name = signal.Signals(signum).name
        self.received += 1
        self.last = name
        if self._ignoring:
            return
        if self._stop is None:
            raise SafetyStop(f"{name} received before the rig started: stopped, torque was off")
        self._while_armed += 1
        if self._while_armed <= 2:
            self._stop(f"{name} received")
            return
        raise SafetyStop(f"{name} received again: stopping the servos with torque off")


def _is_terminal(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, OSError, ValueError):
        return False


def _never_raises(log: Callable[[str], None]) -> Callable[[str], None]:
    """``log`` that drops a line it cannot write (the terminal closed: SIGHUP)."""
    def safe(text: str) -> None:
        with contextlib.suppress(OSError, ValueError):
            log(text)
    return safe


def run_live(parts: RigParts, opts: LiveOptions, clock: Clock | None = None) -> LiveResult:
    """Run the rig once with ``parts`` and ``opts``; returns the summary, also when the
    session failed (``result.error``)."""
    with ExitSignals() as signals:
        return _Session(parts, opts, clock or MonotonicClock(), signals).run()


class _Session:
    def __init__(self, parts: RigParts, opts: LiveOptions, clock: Clock,
                 signals: ExitSignals) -> None:
        self.parts, self.opts, self.clock, self.signals = parts, opts, clock, signals
        self.log = _never_raises(opts.log)
        self.stats = RunStats()
        self.bus_stats: Any = None
        self.glove_stats: Any = None
        self.torque_off: bool | None = None
        self.torque_unconfirmed: list[str] = []  # servos whose torque-off was not read back
        self.stages: dict[str, dict[str, float]] | None = None
        self.snapshots: list[np.ndarray] = []
        self.snapshot_times_s: list[float] = []
        self.outputs: list[Any] = []  # the VMC sender and recorder (closed by the end)
        self.ease_s = 0.0  # the easing to relaxed that ended the run
        self.left_out: list[str] = []  # servos that did not answer at start-up, left out
        self._left_at_start: tuple[int, ...] = ()
        self.admitted: list[str] = []  # of those, the ones admitted when they answered
        self.panel: Any = None  # the LivePanel while it is up
        self.started = False

    def run(self) -> LiveResult:
        error: HandrigError | None = None
        opened: app.OpenedBus | None = None
        try:
            # the checks that need no hardware, before the bus is opened and commissioned
            if self.opts.take is None:
                app.glove_spec(self.opts.glove, self.parts.glove_config, self.parts.glove_file)
            app.check_outputs(self.opts.vmc, self.opts.record)
            if self.opts.record_glove:
                takes.check_glove_take_path(self.opts.record_glove, record=self.opts.record)
            with contextlib.ExitStack() as stack:
                opened = stack.enter_context(app.servo_bus(
                    self.opts.bus, self.parts, self.clock, wire_timing=self.opts.wire_timing,
                    viewer=self.opts.viewer, faults=self.opts.sim_faults, log=self.log,
                    started=self.opts.started))
                error = self._devices_open(stack, opened.bus)
        except HandrigError as exc:
            error = error or exc
        except OSError as exc:  # a device call the driver did not wrap: still a summary
            error = error or DeviceError(f"{type(exc).__name__}: {exc}")
        outputs = app.outputs_summary(self.outputs, self.stats.duration_s)
        summary = app.summary_dict(self.stats, self.bus_stats, self.glove_stats,
                                   self.torque_off, outputs=outputs,
                                   clamped=app.clamped_joints(self.parts.pipeline),
                                   ease_s=self.ease_s)
        glove = self.opts.glove or ""
        recorded = self.opts.recorded or (
            glove.removeprefix("replay:") if glove.startswith("replay:") else "")
        summary["clamp_advice"] = clamp_advice(summary, recorded, self.parts.expander.controls,
                                               self.parts.expander.training_range())
        if self.stages:
            summary["stages_us"] = self.stages
        if self.signals.received:
            summary["signals"] = self.signals.received
        if self.opts.show:
            summary["show"] = self.opts.show
        summary["simulated_bus"] = opened is not None and opened.emulator is not None
        summary["take_played"] = self.opts.take is not None
        if self.left_out:
            summary["servos_left_out"] = self.left_out
        if self.admitted:
            summary["servos_admitted"] = self.admitted
        if self.torque_unconfirmed:
            summary["torque_off_unconfirmed"] = self.torque_unconfirmed
        if error is not None:
            summary["error"] = str(error)
        return LiveResult(summary, self.snapshots,
                          tuple(s.joint for s in self.parts.rig_config.servos),
                          opened.emulator_output() if opened is not None else "",
                          error, self.started, self.snapshot_times_s)

    def _devices_open(self, stack: contextlib.ExitStack, bus: DynamixelBus
                      ) -> HandrigError | None:
        """With the bus open: the glove, commissioning, the outputs, the rig, the run.
        Returns the error the run ended with (torque is off by then)."""
        opts, parts, log = self.opts, self.parts, self.log
        glove = (opts.take(self.clock) if opts.take is not None else
                 app.open_glove(opts.glove, parts.glove_config, self.clock, parts.glove_file))
        stack.enter_context(glove)
        stack.callback(self._glove_figures, glove)
        bus.connect()
        stack.callback(self._bus_figures, bus)  # after torque-off, before the bus closes
        left_out = self._left_at_start = bus.left_out
        self.left_out = [bus.describe(i) for i in left_out]
        header = [f"servo bus {bus.port}: {len(parts.rig_config.servos) - len(left_out)} "
                  f"servos commissioned ({len(bus.commissioning)} settings checked or "
                  "changed)"]
        if left_out and not opts.verbose:  # said once (verbose: the commissioning note)
            log(f"{', '.join(self.left_out)} did not answer at start-up: the run goes on "
                "without it ([silence] action continue); it gets no goal and no torque "
                "until it answers and is commissioned")
        if opts.verbose:
            header[:0] = bus.commissioning
        if not opts.panel:
            for line in header:
                log(line)
        outputs = app.outputs(stack, parts.rig_config, self.clock, vmc=opts.vmc,
                              record=opts.record, log=log,
                              glove_rate_hz=parts.glove_config.glove.rate_hz,
                              record_rate_hz=opts.record_rate_hz)
        if opts.record_glove:
            take = takes.open_glove_take(opts.record_glove, glove, parts.glove_config,
                                         source=opts.glove or glove.name, log=log,
                                         from_first_output=True)
            stack.callback(lambda: log(f"glove take: {take.close()}"))
            outputs.append(take)
        rig = app.build_rig(parts, glove, bus, self.clock, outputs=outputs, log=self._rig_log,
                            profile=opts.profile, ease_in=opts.ease_in)
        self.outputs = list(outputs)
        self.stats = rig.stats
        if opts.on_rig is not None:
            opts.on_rig(rig)
        if opts.snapshot_every > 0:
            rig.outputs = (*rig.outputs, self._snapshots(rig, opts.snapshot_every))
        rig.prepare()  # the garbage collected before torque (and its watchdog) goes on
        stack.callback(gc.unfreeze)  # also when torque-on fails and the loop never runs
        loop = parts.rig_config.loop
        self.signals.arm(rig.request_stop)
        try:
            # the Rig starts from bus.last_goals_deg: where torque-on holds every servo
            with bus.torque(handle_signals=False):
                self.started = True
                try:
                    with (self._console(rig, header) if opts.panel else contextlib.nullcontext(),
                          pinned_loop(loop.pin_cpu, self._rig_log),
                          realtime_priority(loop.realtime_priority, self._rig_log)):
                        rig.run(frames=opts.frames, duration_s=opts.duration_s,
                                done_reason=opts.done_reason)
                    self.ease_s = 0.0 if rig.machine.stop_now else rig.relax_time_s
                finally:
                    self.signals.disarm()  # from here on: torque off, then shut down
        except HandrigError as exc:
            return exc
        finally:
            self.signals.disarm()
            if rig.stage_profile is not None:
                self.stages = rig.stage_profile.summary_us()
        return None

    def _rig_log(self, text: str) -> None:
        """The rig's lines: above the panel while it is up on a terminal, else to the
        session's log."""
        panel = self.panel
        if panel is not None:
            with contextlib.suppress(OSError, ValueError):
                panel.log(text)
        else:
            self.log(text)

    @contextlib.contextmanager
    def _console(self, rig: Any, header: list[str]) -> Iterator[None]:
        """The show console: the panel (on a terminal, else plain lines) and, when stdin
        is a terminal, the show keys."""
        from handrig.app.keys import KeyReader
        from handrig.app.panel import heat_colours, show_panel
        from handrig.app.rig_snapshot import RigSnapshot

        keys: KeyReader | None = None
        if self.opts.keys and _is_terminal(sys.stdin):
            keys = KeyReader.for_show(
                sys.stdin.fileno(), toggle_relax=rig.toggle_relax,
                stop=lambda: rig.request_stop("q pressed"), estop=rig.estop,
                on_error=lambda exc: self._rig_log(f"key failed: {exc}"))
        snapshot = RigSnapshot(rig, glove_source=self.opts.glove or "", keys=keys is not None,
                               show=self.opts.show, **heat_colours(self.parts.rig_config))
        with show_panel(snapshot, header, keys, self.log, self._set_panel):
            yield

    def _set_panel(self, panel: Any) -> None:
        self.panel = panel

    def _bus_figures(self, bus: DynamixelBus) -> None:
        self.torque_off, self.torque_unconfirmed = torque_readback(bus)
        self.admitted = [bus.describe(i) for i in self._left_at_start
                         if i not in bus.left_out]
        self.bus_stats = bus.stats

    def _glove_figures(self, glove: Any) -> None:
        self.glove_stats = glove.stats()

    def _snapshots(self, rig: Any, every: int) -> Callable[[float, np.ndarray], None]:
        counter = [0]

        def snap(t_s: float, pose: np.ndarray) -> None:
            counter[0] += 1
            state = rig.last_state
            if counter[0] % every == 0 and state is not None:
                self.snapshots.append(np.array(state.positions_deg))
                self.snapshot_times_s.append(float(t_s))
        return snap


def _counts(items: dict[str, int]) -> str:
    return ", ".join(f"{n} {what}" for what, n in items.items()) if items else "none"


def _outputs_lines(outputs: dict[str, Any]) -> list[str]:
    vmc, rec = outputs.get("vmc"), outputs.get("recording")
    glove_take = outputs.get("glove_take")
    if vmc:
        rate = f", {vmc['rate_hz']} Hz" if vmc.get("rate_hz") is not None else ""
        errors = f", {vmc['errors']} send errors" if vmc.get("errors") else ""
        vmc_text = f"VMC to {vmc['target']}: {vmc['bundles_sent']} bundles{rate}{errors}"
    else:
        vmc_text = "VMC off"
    if rec:
        duration = f"{rec['duration_s']:.1f} s" if rec.get("duration_s") is not None else "-"
        dropped = (f", {rec['frames_dropped']} frames dropped (disk too slow)"
                   if rec.get("frames_dropped") else "")
        if rec.get("stopped_reason"):
            dropped = f", {rec['frames_dropped']} frames not recorded: {rec['stopped_reason']}"
        rec_text = (f"recording {rec['path']}: {rec['frames']} frames, {duration}, "
                    f"{rec['bytes']} bytes{dropped}")
    else:
        rec_text = "recording off"
    lines = [f"outputs           {vmc_text}", f"                  {rec_text}"]
    if glove_take:
        stopped = f" ({glove_take['stopped_reason']})" if glove_take.get("stopped_reason") else ""
        lines.append(f"                  glove take {glove_take['path']}: {glove_take['frames']}"
                     f" frames, {glove_take['duration_s']:.1f} s{stopped}")
    return lines


CLAMP_RANGE_FRACTION = 0.05
"""Controls outside the map's training range in more than this fraction of frames: the
map is a likely cause of clamps."""


def clamp_advice(summary: dict[str, Any], recording: str, controls: tuple[str, ...],
                 training: Any) -> str:
    """The likely causes of the run's clamps that it can tell: a recorded performance
    (``recording``: the file a replayed or emulated glove streamed), a glove past its
    calibration (a control curve's own servo clamped), a map outside its training range
    (``training``: :meth:`handrig.pose.expand.Expander.training_range`)."""
    if not summary.get("limit_clamps"):
        return "no clamps"
    causes = []
    past = [c["joint"] for c in summary.get("clamped_joints") or [] if c["joint"] in controls]
    at = f" ({', '.join(past)}: a control asked past its joint)" if past else ""
    if recording:
        causes.append(f"a recorded performance ({recording}): the clamps come from the"
                      f" recording{at} and the map, not from a glove on a hand")
    elif past:
        causes.append(f"a glove past its calibration{at}: recalibrate the glove")
    if training.known and training.outside_fraction > CLAMP_RANGE_FRACTION:
        causes.append(f"a map outside its training range (controls beyond it in"
                      f" {training.outside_fraction:.0%} of frames; refit the map on motion"
                      " like this, or check the glove calibration)")
    if not causes:
        causes.append("the map asks for poses past the joints inside its training range"
                      " (check it with handrig evaluate)")
    return "likely: " + "; ".join(causes)


SIMULATED_LINE = ("bus               SIMULATED (--port sim): emulated servos and a MuJoCo "
                  "puppet, no hardware was driven")


def format_summary(summary: dict[str, Any]) -> str:
    """The human-readable summary of a run (the same figures as ``--json``)."""
    lat = summary["latency_us"]
    comp = summary.get("compute_us") or {}
    glove = summary.get("glove", {})
    ease_s = summary.get("ease_s") or 0.0
    ease = (f"; includes the {ease_s:g} s ease to the relaxed pose at the end" if ease_s
            else "; ended at once, no ease")
    clamped = summary.get("clamped_joints") or []
    most = (", most at " + ", ".join(f"{c['joint']} ({c['clamps']})" for c in clamped)
            if clamped else "")
    lines = [
        *([SIMULATED_LINE] if summary.get("simulated_bus") else []),
        *([f"show              {summary['show']}"] if summary.get("show") else []),
        f"frames            {summary['frames']} in {summary['duration_s']} s "
        f"({summary['rate_hz']} Hz, jitter {summary['jitter_us']} us){ease}",
        f"latency           p50 {lat['p50']} us, p99 {lat['p99']} us, max {lat['max']} us "
        "(glove frame's arrival -> Sync Write handed to the OS)",
        f"                  of which compute p50 {comp.get('p50')} us, p99 {comp.get('p99')} us "
        f"(cycle start -> Sync Write; loop {summary.get('loop_mode', 'fixed')})",
        *([f"servos left out   {', '.join(summary['servos_left_out'])} (did not answer at "
            "start-up: no goal, no torque until commissioned)"]
          if summary.get("servos_left_out") else []),
        *([f"  admitted        {', '.join(summary['servos_admitted'])} (answered later: "
            "commissioned, eased in from where it was)"]
          if summary.get("servos_admitted") else []),
        f"frame losses      {summary.get('frames_skipped', 0)} skipped by the loop, "
        f"{summary.get('frames_in_host_stalls', 0)} left waiting by host stalls (the host "
        "read nothing for 3 frame periods or more: not the glove), "
        f"{summary.get('frames_in_bursts', 0)} lost in the glove's own bursts (caught up: "
        f"{summary.get('frames_caught_up', 0)} written just before a newer one)",
        f"overruns          {summary['overruns']} (max {summary['overrun_max_us']} us late, "
        f"{summary['missed_cycles']} cycles missed)",
        f"limit clamps      {summary['limit_clamps']} servo targets held at a joint or servo "
        f"limit{most}",
        *([] if not (summary["limit_clamps"] or summary.get("clamped_joints")
                     or summary.get("clamp_advice", "no clamps") != "no clamps") else [
            "                  (the pose asked past the limit: normal at a full fist or spread"
            + (f"; high all the time: {summary['clamp_advice']})" if "clamp_advice" in summary
               else ")")]),
        f"                  {summary['pose_clamps']} values of the full two-hand pose clamped, "
        f"{summary['bus_clamps']} goals clamped by the driver, {summary['slew_limited']} "
        f"slew-limited, {summary['nonfinite_targets']} non-finite targets held",
        f"take              {glove.get('frames_ok', '-')} frames played, used "
        f"{glove.get('frames_used', '-')}" if summary.get("take_played") else
        f"glove             {glove.get('frames_ok', '-')} frames ok, "
        f"{glove.get('crc_errors', 0)} CRC errors, {glove.get('decode_errors', 0)} other "
        f"errors, {glove.get('resyncs', 0)} resyncs, used {glove.get('frames_used', '-')}",
        f"faults            {_counts(summary.get('faults', {}))}",
        f"tracking          rms {summary['tracking_rms_deg']} deg, max "
        f"{summary['tracking_max_deg']} deg (present vs goal, {summary['reads']} reads, "
        f"{summary['stale_reads']} with stale servos)",
        *_outputs_lines(summary.get("outputs") or {}),
        *_heat_lines(summary.get("heat") or {}),
        f"safety            {summary['relax_events']} relax events (glove lost or servos "
        f"silent), {summary.get('relax_keys', 0)} by the relax key, "
        f"{summary.get('resumes', 0)} resumes, e-stop "
        f"{'pressed' if summary['estop'] else 'not pressed'}, stopped: {summary['stop_reason']}",
        f"torque off        {summary['torque_off']}",
        *([f"  not confirmed   {'; '.join(summary['torque_off_unconfirmed'])}"]
          if summary.get("torque_off_unconfirmed") else []),
    ]
    if "error" in summary:
        lines.append(f"error             {summary['error']}")
    return "\n".join(lines)


def format_hands_summary(summary: dict[str, Any]) -> str:
    """The summary of a two-hand run: a part per hand, then torque and the error."""
    lines = [*([SIMULATED_LINE] if summary.get("simulated_bus") else []),
             *([f"show              {summary['show']}"] if summary.get("show") else [])]
    for name, part in summary["hands"].items():
        part = {k: v for k, v in part.items() if k not in ("show", "simulated_bus")}
        lines.append(f"--- {name} hand ({part.get('glove_source') or 'glove'}) ---")
        lines += [line for line in format_summary(part).splitlines()
                  if not line.startswith(("torque off", "error"))]
    lines.append(f"torque off        {summary['torque_off']} (every servo of both hands)")
    if "error" in summary:
        lines.append(f"error             {summary['error']}")
    return "\n".join(lines)


def _heat_lines(heat: dict[str, Any]) -> list[str]:
    """The ``heat`` line: the hottest servo read and what the [heat] tiers did."""
    if not heat:
        return []
    hottest = heat.get("hottest") or "no temperature read"
    return [f"heat              hottest {hottest}; {heat.get('warnings', 0)} warnings, "
            f"{heat.get('reliefs', 0)} effort caps, {heat.get('actions', 0)} actions "
            "([heat] tiers)"]


def failed(error: HandrigError, parts: RigParts | None = None) -> LiveResult:
    """The result of a session that could not begin (a config, an emulator, a port)."""
    summary = app.summary_dict(RunStats(), None, None, None)
    summary["error"] = str(error)
    joints = tuple(s.joint for s in parts.rig_config.servos) if parts is not None else ()
    return LiveResult(summary, [], joints, error=error)


def print_result(result: LiveResult, as_json: bool) -> int:
    """Print a session's summary (one JSON object with ``as_json``) and return the exit
    status: 0 when it ended cleanly with torque off, 1 when the run ended with an error
    or torque may still be on, 2 when it failed before the rig started. A summary that
    cannot be written (the terminal is gone) is not an error."""
    import json

    summary = result.summary
    with contextlib.suppress(OSError, ValueError):
        if as_json:
            print(json.dumps(summary), flush=True)
        elif result.started:
            print(format_hands_summary(summary) if "hands" in summary
                  else format_summary(summary), flush=True)
        if result.error is not None and (as_json or not result.started):
            print(f"handrig: error: {result.error}", file=sys.stderr, flush=True)
    if result.error is not None and not result.started:
        return 2
    return 1 if result.error is not None or summary["torque_off"] is not True else 0
