"""One live session for any number of hands: devices opened, torque on, the loops run,
torque off, figures out.

Shared by ``handrig run``, ``demo`` and ``play``. The factory (:mod:`handrig.app.factory`)
opens the gloves, the servo buses (with their emulators for ``"sim"``) and the outputs;
:mod:`handrig.app.hands` says what the hands are (:class:`SessionParts`: one hand, the
whole rig on one glove, is N = 1; or a glove per hand). Each hand is its own
:class:`~handrig.loop.rig.Rig` on a :class:`~handrig.devices.servo.bus.ServoBus`: the
first in the caller's thread, the others each in a thread of its own. Hands share a
bus (through :class:`~handrig.devices.servo.shared.SharedBus`, one writer at a time)
or have one each, as the rig file says (``[left_bus]``). The session speaks to the
buses through the ``ServoBus`` contract only: connect, torque, the servos left out,
what connect did, and at the end the torque read back (``confirm_torque_off``). A
session always returns its summary, with the error in it when there was one.

What is per hand: a glove lost, garbled or silent relaxes that hand only and it
resumes on its own; a servo's silence acts on its hand. What is for every hand: the
keys (space relaxes, q stops, e is the e-stop), a signal
(:class:`~handrig.app.session_exit.ExitSignals`), a glove's e-stop button (the other
hands ease and stop too), a loop's failure (the others stop at once), torque (on for
every servo before any loop starts, off for every servo on every way out), the
outputs (VMC and the recording are fed by the first hand's loop, which sends the full
pose). The summary is the first hand's figures, with a part per hand when there are
several, each of the same shape. The emulators run in sessions of their own, so a
Ctrl-C reaches the rig alone and they are stopped after torque is off.
"""

from __future__ import annotations

import contextlib
import dataclasses
import sys
import threading
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from handrig.app import factory as app
from handrig.app import parts as app_parts
from handrig.app import takes
from handrig.app import timecode as app_timecode
from handrig.app.cues.live import CueOptions, LiveCues, open_cues
from handrig.app.factory import OpenedBus
from handrig.app.hands import AllHands, SessionParts, check_gloves, side_control_channels
from handrig.app.layering import LayerControl, LayerOptions
from handrig.app.parts import RigParts
from handrig.app.result import LiveResult
from handrig.app.session_exit import (
    READBACK_BUDGET_S,
    ExitSignals,
    is_terminal,
    never_raises,
)
from handrig.app.summary import (
    clamp_advice,
    clamped_joints,
    outputs_summary,
    summary_dict,
)
from handrig.clock import Clock, MonotonicClock
from handrig.config.rig import hand_of_joint
from handrig.devices.glove import GloveSource
from handrig.devices.servo.bus import ServoBus
from handrig.devices.servo.shared import SharedBus
from handrig.devices.timecode.reader import TimecodeReader
from handrig.errors import ConfigError, DeviceError, HandrigError, TorqueOffError
from handrig.loop.modes import Mode
from handrig.loop.rig import Rig
from handrig.loop.stats import RunStats
from handrig.realtime import cpus_awake_around_frames, pinned_loop, realtime_priority

SWITCH_INTERVAL_S = 0.0005
"""The interpreter's thread switch interval while several loops run: a loop woken by
its glove waits at most this long for another loop to hand over the interpreter
(Python's default, 5 ms, is a whole glove period)."""
NUMBER_WORDS = {1: "one", 2: "two"}

BusOpener = Callable[..., contextlib.AbstractContextManager[OpenedBus]]
"""How a session opens a bus: :func:`handrig.app.factory.servo_bus`'s signature (the
spec, the hand's parts, the clock, and its keywords)."""


@dataclass
class LiveOptions:
    glove: str | None = None  # PORT, opengloves:PORT, replay:FILE (None: glove.toml)
    glove_left: str | None = None  # with a glove per hand: the left hand's glove
    bus_left: str | None = None  # a rig with [left_bus]: the left hand's bus (None: its port)
    show: str = ""  # the show file's name, for the panel (handrig run --show)
    recorded: str = ""  # the recording an emulated glove on ``glove`` streams (handrig demo)
    bus: str | None = None  # PORT or "sim" (None: rig.toml)
    frames: int | None = None
    duration_s: float | None = None
    wire_timing: bool = True  # for the simulated bus
    viewer: bool = False
    vmc: str | None = None
    openxr: str | None = None  # HOST:PORT: the OpenXR hand joints (outputs/openxr.py)
    record: str | None = None
    record_rate_hz: float | None = None  # a BVH take's frame rate (None: the glove's)
    record_glove: str | None = None  # a glove take: what the glove sent (app/takes.py)
    record_glove_left: str | None = None  # with a glove per hand: the left glove's take
    take: Callable[[Clock], GloveSource] | None = None  # handrig play: the take, as the glove
    cues: CueOptions | None = None  # --osc-in, --midi-in: cues acting as the keys do
    layering: LayerOptions | None = None  # takes layered under the glove (app/layering.py)
    timecode: TimecodeReader | None = None  # --ltc: the panel's timecode, a take's stamps
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
    # given the hands' loops once built, by hand key ("ri", "le"; "" for the whole rig
    # on one glove), and the controls that act on every hand as the keys do (the --view)
    on_hands: Callable[[Mapping[str, Rig], AllHands], None] | None = None

    def gloves(self) -> tuple[str | None, str | None]:
        """Each hand's glove spec, right first."""
        return self.glove, self.glove_left

    def glove_takes(self) -> tuple[tuple[str, str | None], tuple[str, str | None]]:
        """Each hand's glove take asked for: (its flag, its path or None)."""
        return ("--record-glove", self.record_glove), ("--record-glove-left",
                                                        self.record_glove_left)


def run_live(parts: RigParts | SessionParts, opts: LiveOptions, clock: Clock | None = None,
             *, open_bus: BusOpener | None = None) -> LiveResult:
    """Run the session once with ``parts`` (a :class:`RigParts`: one hand) and ``opts``;
    returns the summary, also when the session failed (``result.error``). ``open_bus``:
    where the buses come from (default :func:`handrig.app.factory.servo_bus`)."""
    hands = parts if isinstance(parts, SessionParts) else SessionParts.one(parts)
    with ExitSignals() as signals:
        return _Session(hands, opts, clock or MonotonicClock(), signals,
                        open_bus or app.servo_bus).run()


class _Session:
    def __init__(self, parts: SessionParts, opts: LiveOptions, clock: Clock,
                 signals: ExitSignals, open_bus: BusOpener) -> None:
        self.parts, self.opts, self.clock, self.signals = parts, opts, clock, signals
        self.open_bus = open_bus
        self.log = never_raises(opts.log)
        n = self.n = len(parts.hands)
        self.rigs: list[Rig] = []
        self.stats = [RunStats() for _ in range(n)]
        self.glove_stats: list[Any] = [None] * n
        self.bus_stats: list[Any] = [None] * n  # each hand's bus's counters (shared: the same)
        self.bus_of: list[int] = [-1] * n  # each hand's bus (an index into self.opened)
        self.opened: list[OpenedBus] = []
        self.torque_off: dict[int, bool | None] = {}  # per bus (index), read back
        self.unconfirmed: list[list[str]] = [[] for _ in range(n)]  # torque-off not read
        self.left_out: list[list[str]] = [[] for _ in range(n)]  # silent at start-up
        self.admitted: list[list[str]] = [[] for _ in range(n)]  # of those, answered later
        self._left_at_start: list[tuple[int, ...]] = []  # per bus
        self.stages: list[dict[str, dict[str, float]] | None] = [None] * n
        self.outputs: list[list[Any]] = [[] for _ in range(n)]  # each hand's loop's
        self.snapshots: list[np.ndarray] = []
        self.snapshot_times_s: list[float] = []
        self.ease_s = [0.0] * n  # the easing to relaxed that ended each hand's run
        self.errors: dict[int, BaseException] = {}
        self.panel: Any = None  # the LivePanel while it is up
        self.started = False
        self.all = AllHands(self.rigs)
        self.specs: tuple[str, ...] = ()  # each hand's glove, checked
        self.cues: LiveCues | None = None

    # -- the session --------------------------------------------------------------------
    def run(self) -> LiveResult:
        error: HandrigError | None = None
        try:
            # the checks that need no hardware, before a bus is opened and commissioned
            specs = self._check_gloves()
            app_parts.check_outputs(self.opts.vmc, self.opts.record, self.opts.openxr)
            self._check_glove_takes()
            self.layering = LayerControl.for_session(self.parts, self.opts.layering)
            with contextlib.ExitStack() as stack:
                self._open_buses(stack)
                error = self._devices_open(stack, specs)
        except HandrigError as exc:  # a later failure outranks a lost acknowledgement
            error = exc if error is None or isinstance(error, TorqueOffError) else error
        except OSError as exc:  # a device call the driver did not wrap: still a summary
            if error is None or isinstance(error, TorqueOffError):
                error = DeviceError(f"{type(exc).__name__}: {exc}")
        return self._result(error)

    def _check_gloves(self) -> tuple[str, ...]:
        if self.opts.take is None:
            return check_gloves(self.parts, self.opts.gloves()[:self.n])
        if self.n > 1:
            raise ConfigError("a take is played as one glove", key="take",
                              allowed="a rig on one glove")
        return (self.opts.glove or "",)

    def _glove_takes(self) -> dict[int, tuple[str, str]]:
        """hand -> (flag, path) of the glove takes asked for."""
        return {i: (flag, path) for i, (flag, path) in enumerate(self.opts.glove_takes())
                if path and i < self.n}

    def _check_glove_takes(self) -> None:
        """Before any bus opens: each take a new .csv, not the performance's, not another
        hand's (ConfigError naming the flag)."""
        seen: dict[Path, str] = {}
        for flag, path in self._glove_takes().values():
            takes.check_glove_take_path(path, flag, record=self.opts.record)
            where = Path(path).resolve()
            if where in seen:
                raise ConfigError(f"the same file as {seen[where]}", key=flag, value=path,
                                  allowed="a file of its own: a glove take per hand")
            seen[where] = flag

    def _open_buses(self, stack: contextlib.ExitStack) -> None:
        """The buses, opened (not yet connected), as the rig file groups the hands."""
        opts, parts = self.opts, self.parts
        specs = (opts.bus, opts.bus_left)
        for b, group in enumerate(parts.buses):
            if len(group) == 1:
                on, spec = parts.hands[group[0]], specs[group[0]]
            else:  # the whole rig's servos on one bus
                on = dataclasses.replace(parts.hands[0], rig_config=parts.rig_config,
                                         hand=None)
                spec = opts.bus
            log = self._prefixed(group[0]) if len(parts.buses) > 1 else self.log
            self.opened.append(stack.enter_context(self.open_bus(
                spec, on, self.clock, wire_timing=opts.wire_timing, viewer=opts.viewer,
                faults=opts.sim_faults, log=log, started=opts.started)))
            for i in group:
                self.bus_of[i] = b

    def _prefixed(self, i: int) -> Callable[[str], None]:
        name = self.parts.name(i)
        return lambda text: self.log(f"{name} hand: {text}")

    def _mine(self, i: int, bus: ServoBus) -> list[int]:
        """The servos (bus indices) of hand ``i`` on its bus."""
        key = self.parts.key(i)
        shared = len(self.parts.buses[self.bus_of[i]]) > 1
        return [k for k, j in enumerate(bus.joint_names)
                if not shared or hand_of_joint(j) == key]

    def _connect(self, stack: contextlib.ExitStack) -> tuple[list[ServoBus], list[str]]:
        """Every bus connected (commissioned); each hand's bus (a shared bus cut into its
        hands' parts), and the header lines."""
        opts, parts, log = self.opts, self.parts, self.log
        header: list[str] = []
        hand_buses: list[ServoBus | None] = [None] * self.n
        for b, opened in enumerate(self.opened):
            bus = opened.bus
            bus.connect()
            stack.callback(self._bus_figures, b)  # after torque-off, before the bus closes
            left_out = bus.left_out
            self._left_at_start.append(left_out)
            group = parts.buses[b]
            for i in group:
                mine = set(self._mine(i, bus))
                self.left_out[i] = [bus.describe(k) for k in left_out if k in mine]
            if left_out and not opts.verbose:  # said once (verbose: the commissioning note)
                log(f"{', '.join(bus.describe(k) for k in left_out)} did not answer at "
                    "start-up: the run goes on without it ([silence] action continue); it "
                    "gets no goal and no torque until it answers and is commissioned")
            if opts.verbose:
                header += bus.connect_notes
            header.append(f"servo bus {bus.port}: {bus.n_servos - len(left_out)} servos "
                          f"commissioned ({len(bus.connect_notes)} settings checked or "
                          "changed)")
            if len(group) == 1:
                hand_buses[group[0]] = bus
                continue
            shared = SharedBus(bus, self.clock)
            for i in group:
                hand_buses[i] = shared.part(self._mine(i, bus))
        if self.n > 1:
            gloves = ", ".join(f"{parts.name(i)} glove {spec}"
                               for i, spec in enumerate(self.specs))
            first = self.opened[0].bus
            header.append(f"{NUMBER_WORDS.get(self.n, str(self.n))} hands: {gloves}; map "
                          f"{parts.map_file.name}; "
                          + ("a bus each, a writer each" if len(self.opened) > 1
                             else f"one bus at {first.baud} baud, shared"))
        buses = [b for b in hand_buses if b is not None]
        if len(buses) != self.n:
            raise DeviceError("a hand has no bus: the rig file's buses and hands disagree")
        return buses, header

    def _devices_open(self, stack: contextlib.ExitStack, specs: tuple[str, ...]
                      ) -> HandrigError | None:
        """With the buses open: the gloves, commissioning, the outputs, the loops, the
        run. Returns the error the run ended with (torque is off by then)."""
        opts, parts, log = self.opts, self.parts, self.log
        self.specs = specs
        gloves = []
        for i, side in enumerate(parts.hands):
            glove = (opts.take(self.clock) if opts.take is not None else
                     app.open_glove(specs[i], side.glove_config, self.clock, side.glove_file))
            stack.enter_context(glove)
            stack.callback(self._glove_figures, i, glove)
            gloves.append(glove)
        buses, header = self._connect(stack)
        if not opts.panel:
            for line in header:
                log(line)
        first = parts.hands[0]
        self.outputs[0] = app.outputs(stack, parts.rig_config, self.clock, vmc=opts.vmc,
                                      record=opts.record, log=log,
                                      glove_rate_hz=first.glove_config.glove.rate_hz,
                                      record_rate_hz=opts.record_rate_hz, openxr=opts.openxr)
        rate_hz = app.take_rate_hz(parts.rig_config, first.glove_config.glove.rate_hz,
                                   opts.record_rate_hz)
        self.cues = open_cues(stack, opts.cues, self.all, self.clock, self.outputs[0],
                              rate_hz, self._hand_log(0), parts.rig_config.loop)
        if opts.timecode is not None:  # app/timecode.py: started, closed by the stack
            self.outputs[0].append(app_timecode.stamp_output(stack, opts.timecode, self.clock,
                                                             opts.record, log))
        for i, (_, path) in self._glove_takes().items():
            take = takes.open_glove_take(path, gloves[i], parts.hands[i].glove_config,
                                         source=opts.gloves()[i] or gloves[i].name, log=log,
                                         from_first_output=True)
            what = " ".join(w for w in (parts.name(i), "glove take") if w)
            stack.callback(_close_take, take, what, log)
            self.outputs[i].append(take)
        for i, side in enumerate(parts.hands):
            rig = Rig.from_config(
                side.rig_config, gloves[i], buses[i], side.pipeline, self.clock,
                controls_from_raw=side.controls, orientation=side.orientation,
                outputs=self.outputs[i], log=self._hand_log(i), profile=opts.profile,
                ease_in=opts.ease_in, raw_channels=side_control_channels(side),
                gravity=side.gravity)
            self.rigs.append(rig)
            self.stats[i] = rig.stats
        self.layering.connect(self.rigs)
        if opts.on_hands is not None:
            opts.on_hands({parts.key(i): rig for i, rig in enumerate(self.rigs)}, self.all)
        if opts.snapshot_every > 0:  # on the first hand's loop: every hand's positions
            first_rig = self.rigs[0]
            first_rig.outputs = (*first_rig.outputs, self._snapshots(opts.snapshot_every))
        if self.cues is not None:  # /handrig/play and /handrig/layer act on the layers
            self.cues.attach_layers(self.layering.play, self.layering.layer)
            self.cues.start()
        for rig in self.rigs:
            rig.prepare()  # the garbage collected before torque (and its watchdog) goes on
        stack.callback(_unfreeze)  # also when torque-on fails and the loop never runs
        if opts.panel:  # loaded now: an import under torque delays the first goals
            import handrig.app.keys
            import handrig.app.panel
            import handrig.app.rig_snapshot  # noqa: F401
        self.signals.arm(self.all.request_stop)
        return self._under_torque(header)

    def _under_torque(self, header: list[str]) -> HandrigError | None:
        """Torque on for every bus, the loops run, torque off on every way out."""
        old_switch = sys.getswitchinterval()
        unacknowledged: TorqueOffError | None = None
        try:
            # each Rig starts from its bus's last_goals_deg: where torque-on holds it
            with contextlib.ExitStack() as torque:
                for opened in self.opened:
                    torque.enter_context(opened.bus.torque(handle_signals=False))
                self.started = True
                try:
                    with self._console(header) if self.opts.panel else contextlib.nullcontext():
                        if self.n > 1:
                            sys.setswitchinterval(SWITCH_INTERVAL_S)
                        self._run_hands()
                finally:
                    sys.setswitchinterval(old_switch)
                    self.signals.disarm()  # from here on: torque off, then shut down
        except TorqueOffError as exc:  # after the hands' own errors; the read-back judges it
            unacknowledged = exc
        except HandrigError as exc:
            return exc
        finally:
            self.signals.disarm()
            for i, rig in enumerate(self.rigs):
                if rig.stage_profile is not None:
                    self.stages[i] = rig.stage_profile.summary_us()
        for i in range(self.n):
            failure = self.errors.get(i)
            if failure is not None:
                if isinstance(failure, HandrigError):
                    return failure
                raise failure
        return unacknowledged

    def _run_hands(self) -> None:
        """The first hand's loop in this thread, every other in a thread of its own."""
        others = [threading.Thread(target=self._run_hand, args=(i,),
                                   name=f"handrig-{self.parts.name(i)}-hand", daemon=True)
                  for i in range(1, self.n)]
        for thread in others:
            thread.start()
        try:
            self._run_hand(0)
        finally:
            for thread in others:
                while thread.is_alive():
                    thread.join(timeout=0.1)

    def _run_hand(self, i: int) -> None:
        opts, rig = self.opts, self.rigs[i]
        others = [r for k, r in enumerate(self.rigs) if k != i]
        loop = self.parts.rig_config.loop
        name = self.parts.name(i)
        log = self._hand_log(i)
        try:
            with (pinned_loop(loop.pin_cpu, log),
                  realtime_priority(loop.realtime_priority, log, short_slice_instead=True),
                  cpus_awake_around_frames(loop.keep_cpus_awake and loop.mode == "glove"
                                           and loop.warm_up_us > 0, log) as wake):
                rig.keep_awake(wake)
                try:
                    rig.run(frames=opts.frames, duration_s=opts.duration_s,
                            done_reason=opts.done_reason)
                finally:
                    if wake.error:
                        log(f"the request to keep the CPUs awake failed after {wake.holds} "
                            f"frames ({wake.error}): not kept awake from then on")
            self.ease_s[i] = 0.0 if rig.machine.stop_now else rig.relax_time_s
        except BaseException as exc:  # handed to the session; the other hands stop at once
            self.errors[i] = exc
            for other in others:
                other.estop(f"the {name} hand's loop stopped: {exc}")
            return
        for other in others:
            if rig.machine.estop:
                if not self.all.estop_reason:  # else all were e-stopped: each its reason
                    other.estop(f"the {name} hand's e-stop")
            elif other.machine.stop_requests == 0 and other.mode is not Mode.STOPPING:
                # asked once only: a second request would cut the other hand's ease short
                other.request_stop(f"the {name} hand stopped: {rig.machine.stop_reason}")

    def _hand_log(self, i: int) -> Callable[[str], None]:
        """A hand's loop's lines (named by hand when there are several): above the panel
        while it is up on a terminal, else to the session's log."""
        prefix = f"{self.parts.name(i)} hand: " if self.n > 1 else ""

        def log(text: str) -> None:
            panel = self.panel
            if panel is not None:
                with contextlib.suppress(OSError, ValueError):
                    panel.log(prefix + text)
            else:
                self.log(prefix + text)
        return log

    @contextlib.contextmanager
    def _console(self, header: list[str]) -> Iterator[None]:
        """The show console: the panel (on a terminal, else plain lines) and, when stdin
        is a terminal, the show keys, acting on every hand."""
        from handrig.app.keys import KeyReader
        from handrig.app.panel import heat_colours, show_panel
        from handrig.app.rig_snapshot import HandsSnapshot, RigSnapshot

        keys: KeyReader | None = None
        if self.opts.keys and is_terminal(sys.stdin):
            keys = KeyReader.for_show(
                sys.stdin.fileno(), toggle_relax=self.all.toggle_relax,
                stop=lambda: self.all.request_stop("q pressed"), estop=self.all.estop,
                record=self.cues.record_key if self.cues is not None else None,
                on_error=lambda exc: self._hand_log(0)(f"key failed: {exc}"))
        sources = self.opts.gloves()
        snapshot = HandsSnapshot(
            {self.parts.key(i): RigSnapshot(
                rig, glove_source=sources[i] or "", keys=keys is not None,
                show=self.opts.show, **heat_colours(self.parts.hands[i].rig_config))
             for i, rig in enumerate(self.rigs)},
            keys=keys is not None, show=self.opts.show,
            cues=self.cues.recent if self.cues is not None else None)
        with show_panel(snapshot, header, keys, self.log, self._set_panel):
            yield

    def _set_panel(self, panel: Any) -> None:
        self.panel = panel

    def _bus_figures(self, b: int) -> None:
        bus = self.opened[b].bus
        off, unconfirmed = bus.confirm_torque_off(READBACK_BUDGET_S)
        self.torque_off[b] = off
        at_start = self._left_at_start[b]
        stats = bus.stats
        for i in self.parts.buses[b]:
            mine = self._mine(i, bus)
            names = tuple(f"{bus.describe(k)}:" for k in mine)
            self.bus_stats[i] = stats
            self.unconfirmed[i] = [u for u in unconfirmed if u.startswith(names)]
            self.admitted[i] = [bus.describe(k) for k in at_start
                                if k not in bus.left_out and k in mine]

    def _glove_figures(self, i: int, glove: Any) -> None:
        self.glove_stats[i] = glove.stats()

    # -- the summary --------------------------------------------------------------------
    def _hand_torque_off(self, i: int) -> bool | None:
        return self.torque_off.get(self.bus_of[i])

    def _hand_summary(self, i: int) -> dict[str, Any]:
        """Hand ``i``'s figures: the same keys for every hand."""
        side, opts = self.parts.hands[i], self.opts
        stats = self.stats[i]
        s = summary_dict(stats, self.bus_stats[i], self.glove_stats[i],
                         self._hand_torque_off(i),
                         outputs=outputs_summary(self.outputs[i], stats.duration_s),
                         clamped=clamped_joints(side.pipeline), ease_s=self.ease_s[i])
        glove = opts.gloves()[i] or ""
        recorded = opts.recorded or (
            glove.removeprefix("replay:") if glove.startswith("replay:") else "")
        s["clamp_advice"] = clamp_advice(s, recorded, tuple(side.expander.controls),
                                         side.expander.training_range())
        s["glove_source"] = glove
        s["simulated_bus"] = (self.bus_of[i] >= 0
                              and self.opened[self.bus_of[i]].emulator is not None)
        s["take_played"] = opts.take is not None
        for key, value in (("stages_us", self.stages[i]),
                           ("servos_left_out", self.left_out[i]),
                           ("servos_admitted", self.admitted[i]),
                           ("torque_off_unconfirmed", self.unconfirmed[i])):
            if value:
                s[key] = value
        return s

    def _result(self, error: HandrigError | None) -> LiveResult:
        parts = self.parts
        hands = [self._hand_summary(i) for i in range(self.n)]
        summary = dict(hands[0])
        offs = list(self.torque_off.values())
        summary["torque_off"] = (None if not offs or len(offs) < len(self.opened)
                                 else False if False in offs
                                 else None if None in offs else True)
        summary["simulated_bus"] = any(h["simulated_bus"] for h in hands)
        if self.n > 1:
            summary["hands"] = {parts.name(i): s for i, s in enumerate(hands)}
            summary["buses"] = NUMBER_WORDS.get(len(parts.buses), str(len(parts.buses)))
        if self.opts.show:
            summary["show"] = self.opts.show
        if self.signals.received:
            summary["signals"] = self.signals.received
        if self.cues is not None and self.cues.used:
            summary["cues"] = self.cues.summary()
        if isinstance(error, TorqueOffError) and summary["torque_off"] is True:
            # the torque-off writes went unacknowledged, yet every servo read Torque
            # Enable 0 back: the acknowledgements were lost (a starved host), torque is off
            summary["torque_off_note"] = (f"{error}; read back at exit, every servo's "
                                          "torque is off: only the acknowledgements were lost")
            error = None
        if error is not None:
            summary["error"] = str(error)
        joints = tuple(s.joint for side in parts.hands for s in side.rig_config.servos)
        return LiveResult(summary, self.snapshots, joints,
                          "".join(o.emulator_output() for o in self.opened), error,
                          self.started, self.snapshot_times_s)

    def _snapshots(self, every: int) -> Callable[[float, np.ndarray], None]:
        """An output for the first hand's loop: every ``every`` frames, every hand's
        present positions (in hand order, the order of the result's joint names)."""
        counter = [0]

        def snap(t_s: float, pose: np.ndarray) -> None:
            counter[0] += 1
            states = [rig.last_state for rig in self.rigs]
            if counter[0] % every == 0 and all(st is not None for st in states):
                self.snapshots.append(np.concatenate(
                    [np.asarray(st.positions_deg) for st in states if st is not None]))
                self.snapshot_times_s.append(float(t_s))
        return snap


def _close_take(take: Any, what: str, log: Callable[[str], None]) -> None:
    log(f"{what}: {take.close()}")


def _unfreeze() -> None:
    import gc

    gc.unfreeze()
