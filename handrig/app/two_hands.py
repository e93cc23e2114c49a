"""One live session with a glove per hand: two loops, one process.

The rig is cut into its two hands (:mod:`handrig.app.hands`); each hand runs its own
:class:`~handrig.loop.rig.Rig` (its glove's frames start its cycles, its mode machine
relaxes and resumes it, its silence tiers watch its servos) in a thread of its own,
the right hand's in the caller's thread. The servos are on one bus (both loops
write through :class:`~handrig.devices.servo.shared.SharedBus`, one writer at a
time on the wire) or on two (``[left_bus]``: each loop has its bus and writer to
itself, so neither hand waits for the other's wire).

What is per hand: a glove lost, garbled or silent relaxes that hand only and it
resumes on its own; a servo's silence acts on its hand. What is for both: the keys
(space relaxes both, q stops both, e is the e-stop), a signal, a glove's e-stop
button (the other hand eases and stops too), a loop's failure (the other stops at
once), torque (on for every servo before either loop starts, off for every servo on
every way out), the outputs (VMC and the recording carry both hands: the right
hand's loop sends the full pose, its left hand from the left glove's controls and
forearm). The summary has a part per hand.
"""

from __future__ import annotations

import contextlib
import dataclasses
import gc
import sys
import threading
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from handrig.app import factory as app
from handrig.app import takes
from handrig.app.hands import HAND_NAMES, TwoHandParts, check_two_gloves, side_control_channels
from handrig.app.session import (
    ExitSignals,
    LiveOptions,
    LiveResult,
    _is_terminal,
    _never_raises,
    clamp_advice,
    torque_is_off,
)
from handrig.clock import Clock, MonotonicClock
from handrig.config.rig import hand_of_joint
from handrig.devices.servo import DynamixelBus
from handrig.devices.servo.bus import ServoBus
from handrig.devices.servo.shared import SharedBus
from handrig.errors import ConfigError, DeviceError, HandrigError
from handrig.loop.modes import Mode
from handrig.loop.rig import Rig
from handrig.loop.stats import RunStats
from handrig.realtime import pinned_loop, realtime_priority

HANDS = ("ri", "le")
SWITCH_INTERVAL_S = 0.0005
"""The interpreter's thread switch interval while two loops run: a loop woken by its
glove waits at most this long for the other loop to hand over the interpreter
(Python's default, 5 ms, is a whole glove period)."""


def run_two_hands(parts: TwoHandParts, opts: LiveOptions,
                  clock: Clock | None = None) -> LiveResult:
    """Run both hands once with ``parts`` and ``opts`` (``opts.glove`` the right glove,
    ``opts.glove_left`` the left; ``opts.bus`` and ``opts.bus_left`` the ports); returns
    the summary, also when the session failed (``result.error``)."""
    with ExitSignals() as signals:
        return _TwoHands(parts, opts, clock or MonotonicClock(), signals).run()


class BothHands:
    """The show's controls acting on both hands at once (the keys, the view's buttons):
    relax/resume both, stop both (each eases down), e-stop both. Safe from any thread,
    as each rig's are."""

    def __init__(self, rigs: Mapping[str, Rig]) -> None:
        self.rigs = rigs  # filled once the loops are built
        self.estop_reason = ""  # set before either rig is e-stopped

    def toggle_relax(self) -> None:
        for rig in self.rigs.values():
            rig.toggle_relax()

    def request_stop(self, reason: str = "stop requested") -> None:
        for rig in self.rigs.values():
            rig.request_stop(reason)

    def estop(self, reason: str = "e-stop key") -> None:
        self.estop_reason = reason
        for rig in self.rigs.values():
            rig.estop(reason)


class _TwoHands:
    def __init__(self, parts: TwoHandParts, opts: LiveOptions, clock: Clock,
                 signals: ExitSignals) -> None:
        self.parts, self.opts, self.clock, self.signals = parts, opts, clock, signals
        self.log = _never_raises(opts.log)
        self.rigs: dict[str, Rig] = {}
        self.stats: dict[str, RunStats] = {h: RunStats() for h in HANDS}
        self.glove_stats: dict[str, Any] = {}
        self.bus_stats: dict[str, Any] = {}  # per hand: its bus's counters (shared: the same)
        self.torque_off: dict[str, bool | None] = {}  # per bus port
        self.outputs: dict[str, list[Any]] = {"ri": [], "le": []}  # each hand's loop's
        self.snapshots: list[np.ndarray] = []  # both hands' present positions (--render)
        self.snapshot_times_s: list[float] = []
        self.ease_s: dict[str, float] = {h: 0.0 for h in HANDS}
        self.errors: dict[str, BaseException] = {}
        self.opened: list[app.OpenedBus] = []  # read once the emulators have stopped
        self.bus_hands: dict[str, tuple[str, ...]] = {}  # bus port -> the hands on it
        self.panel: Any = None
        self.started = False
        self.both = BothHands(self.rigs)  # the keys' and the view's buttons

    # -- the session --------------------------------------------------------------------
    def run(self) -> LiveResult:
        error: HandrigError | None = None
        try:
            sides = self.parts.sides
            specs = check_two_gloves(self.opts.glove or "", self.opts.glove_left or "",
                                     sides["ri"].glove_config, sides["le"].glove_config,
                                     sides["ri"].glove_file, sides["le"].glove_file)
            app.check_outputs(self.opts.vmc, self.opts.record)
            self._check_glove_takes()
            with contextlib.ExitStack() as stack:
                buses, owners = self._open_buses(stack)
                error = self._devices_open(stack, dict(zip(HANDS, specs, strict=True)),
                                           buses, owners)
        except HandrigError as exc:
            error = error or exc
        except OSError as exc:
            error = error or DeviceError(f"{type(exc).__name__}: {exc}")
        return self._result(error)

    def _glove_takes(self) -> dict[str, tuple[str, str]]:
        """hand -> (flag, path) of the glove takes asked for."""
        asked = {"ri": ("--record-glove", self.opts.record_glove),
                 "le": ("--record-glove-left", self.opts.record_glove_left)}
        return {h: (flag, path) for h, (flag, path) in asked.items() if path}

    def _check_glove_takes(self) -> None:
        """Before any bus opens: each take a new .csv, not the performance's, not the
        other hand's (ConfigError naming the flag)."""
        wanted = self._glove_takes()
        for flag, path in wanted.values():
            takes.check_glove_take_path(path, flag, record=self.opts.record)
        if len(wanted) == 2 and (Path(wanted["ri"][1]).resolve()
                                 == Path(wanted["le"][1]).resolve()):
            raise ConfigError("the same file as --record-glove", key="--record-glove-left",
                              value=wanted["le"][1],
                              allowed="a file of its own: a glove take per hand")

    def _open_buses(self, stack: contextlib.ExitStack
                    ) -> tuple[dict[str, ServoBus | None], list[DynamixelBus]]:
        """The bus or buses, opened (not yet connected): hand -> its bus (None until
        the shared bus is connected and cut), and the buses this session owns."""
        opts, parts = self.opts, self.parts
        if parts.two_buses:
            buses: dict[str, ServoBus | None] = {}
            owners = []
            for h, spec in (("ri", opts.bus), ("le", opts.bus_left)):
                side = parts.sides[h]
                opened = stack.enter_context(app.servo_bus(
                    spec, side, self.clock, wire_timing=opts.wire_timing,
                    viewer=opts.viewer, faults=opts.sim_faults,
                    log=self._prefixed(h), started=opts.started))
                self.opened.append(opened)
                buses[h] = opened.bus
                owners.append(opened.bus)
                self.bus_hands[opened.bus.port] = (h,)
            return buses, owners
        whole = dataclasses.replace(parts.sides["ri"], rig_config=parts.rig_config,
                                    hand=None)
        opened = stack.enter_context(app.servo_bus(
            opts.bus, whole, self.clock, wire_timing=opts.wire_timing, viewer=opts.viewer,
            faults=opts.sim_faults, log=self.log, started=opts.started))
        self.opened.append(opened)
        self.bus_hands[opened.bus.port] = HANDS
        return {"ri": None, "le": None}, [opened.bus]

    def _prefixed(self, h: str) -> Callable[[str], None]:
        return lambda text: self.log(f"{HAND_NAMES[h]} hand: {text}")

    def _devices_open(self, stack: contextlib.ExitStack, specs: dict[str, str],
                      buses: dict[str, ServoBus | None], owners: list[DynamixelBus]
                      ) -> HandrigError | None:
        opts, parts, log = self.opts, self.parts, self.log
        gloves = {}
        for h in HANDS:
            side = parts.sides[h]
            glove = app.open_glove(specs[h], side.glove_config, self.clock, side.glove_file)
            stack.enter_context(glove)
            stack.callback(self._glove_figures, h, glove)
            gloves[h] = glove
        header = []
        for bus in owners:
            bus.connect()
            stack.callback(self._bus_figures, bus)  # after torque-off, before it closes
            header.append(f"servo bus {bus.port}: {bus.n_servos - len(bus.left_out)} "
                          f"servos commissioned ({len(bus.commissioning)} settings checked "
                          "or changed)")
            if bus.left_out:
                log(f"{', '.join(bus.describe(i) for i in bus.left_out)} did not answer at "
                    "start-up: the run goes on without it ([silence] action continue)")
        if not parts.two_buses:
            shared = SharedBus(owners[0], self.clock)
            joints = owners[0].joint_names
            for h in HANDS:
                buses[h] = shared.part([i for i, j in enumerate(joints)
                                        if hand_of_joint(j) == h])
        header.append(f"two hands: right glove {specs['ri']}, left glove {specs['le']}; "
                      f"map {parts.map_file.name}; "
                      + ("two buses, a writer each" if parts.two_buses
                         else f"one bus at {owners[0].baud} baud, shared"))
        if not opts.panel:
            for line in header:
                log(line)
        glove_rate = parts.sides["ri"].glove_config.glove.rate_hz
        outputs = app.outputs(stack, parts.rig_config, self.clock, vmc=opts.vmc,
                              record=opts.record, log=log, glove_rate_hz=glove_rate,
                              record_rate_hz=opts.record_rate_hz)
        self.outputs = {"ri": list(outputs), "le": []}
        for h, (_, path) in self._glove_takes().items():
            take = takes.open_glove_take(path, gloves[h], parts.sides[h].glove_config,
                                         source=specs[h], log=log, from_first_output=True)
            stack.callback(_close_take, take, f"{HAND_NAMES[h]} glove take", log)
            self.outputs[h].append(take)
        for h in HANDS:
            side = parts.sides[h]
            hand_bus = buses[h]
            assert hand_bus is not None
            self.rigs[h] = Rig.from_config(
                side.rig_config, gloves[h], hand_bus, side.pipeline, self.clock,
                controls_from_raw=side.controls, orientation=side.orientation,
                outputs=self.outputs[h], log=self._side_log(h),
                profile=opts.profile, ease_in=opts.ease_in,
                raw_channels=side_control_channels(side))
            self.stats[h] = self.rigs[h].stats
        if opts.snapshot_every > 0:  # on the right hand's loop: both hands' positions
            right = self.rigs["ri"]
            right.outputs = (*right.outputs, self._snapshots(opts.snapshot_every))
        if opts.on_hands is not None:
            opts.on_hands(dict(self.rigs), self.both)
        gc.collect()
        for rig in self.rigs.values():
            rig.prepare()
        stack.callback(gc.unfreeze)
        if opts.panel:  # loaded now: an import under torque delays the first goals
            import handrig.app.keys
            import handrig.app.panel
            import handrig.app.rig_snapshot  # noqa: F401
        self.signals.arm(self._stop_both)
        old_switch = sys.getswitchinterval()
        try:
            with contextlib.ExitStack() as torque:
                for bus in owners:
                    torque.enter_context(bus.torque(handle_signals=False))
                self.started = True
                try:
                    with self._console(header) if opts.panel else contextlib.nullcontext():
                        sys.setswitchinterval(SWITCH_INTERVAL_S)
                        self._run_both()
                finally:
                    sys.setswitchinterval(old_switch)
                    self.signals.disarm()
        except HandrigError as exc:
            return exc
        finally:
            self.signals.disarm()
        for h in HANDS:
            failure = self.errors.get(h)
            if failure is not None:
                if isinstance(failure, HandrigError):
                    return failure
                raise failure
        return None

    def _run_both(self) -> None:
        left = threading.Thread(target=self._run_side, args=("le",),
                                name="handrig-left-hand", daemon=True)
        left.start()
        try:
            self._run_side("ri")
        finally:
            while left.is_alive():
                left.join(timeout=0.1)

    def _run_side(self, h: str) -> None:
        opts = self.opts
        rig, other = self.rigs[h], self.rigs["le" if h == "ri" else "ri"]
        loop = self.parts.rig_config.loop
        name = HAND_NAMES[h]
        try:
            with (pinned_loop(loop.pin_cpu, self._side_log(h)),
                  realtime_priority(loop.realtime_priority, self._side_log(h))):
                rig.run(frames=opts.frames, duration_s=opts.duration_s)
            self.ease_s[h] = 0.0 if rig.machine.stop_now else rig.relax_time_s
        except BaseException as exc:  # handed to the session; the other hand stops at once
            self.errors[h] = exc
            other.estop(f"the {name} hand's loop stopped: {exc}")
            return
        if rig.machine.estop:
            if not self.both.estop_reason:  # else both were e-stopped: each keeps its reason
                other.estop(f"the {name} hand's e-stop")
        elif other.machine.stop_requests == 0 and other.mode is not Mode.STOPPING:
            # asked once only: a second request would cut the other hand's ease short
            other.request_stop(f"the {name} hand stopped: {rig.machine.stop_reason}")

    def _stop_both(self, reason: str) -> None:
        self.both.request_stop(reason)

    def _relax_both(self) -> None:
        self.both.toggle_relax()

    def _estop_both(self) -> None:
        self.both.estop()

    def _side_log(self, h: str) -> Callable[[str], None]:
        def log(text: str) -> None:
            line = f"{HAND_NAMES[h]} hand: {text}"
            panel = self.panel
            if panel is not None:
                with contextlib.suppress(OSError, ValueError):
                    panel.log(line)
            else:
                self.log(line)
        return log

    @contextlib.contextmanager
    def _console(self, header: list[str]) -> Iterator[None]:
        from handrig.app.keys import KeyReader
        from handrig.app.panel import heat_colours, show_panel
        from handrig.app.rig_snapshot import HandsSnapshot, RigSnapshot

        keys: KeyReader | None = None
        rigs = self.rigs
        if self.opts.keys and _is_terminal(sys.stdin):
            keys = KeyReader.for_show(
                sys.stdin.fileno(),
                toggle_relax=self._relax_both, stop=lambda: self._stop_both("q pressed"),
                estop=self._estop_both,
                on_error=lambda exc: self.log(f"key failed: {exc}"))
        sources = {"ri": self.opts.glove or "", "le": self.opts.glove_left or ""}
        snapshot = HandsSnapshot(
            {h: RigSnapshot(rigs[h], glove_source=sources[h],
                            **heat_colours(self.parts.sides[h].rig_config)) for h in HANDS},
            keys=keys is not None, show=self.opts.show)
        with show_panel(snapshot, header, keys, self.log, self._set_panel):
            yield

    def _set_panel(self, panel: Any) -> None:
        self.panel = panel

    def _bus_figures(self, bus: DynamixelBus) -> None:
        self.torque_off[bus.port] = torque_is_off(bus)
        for h in self.bus_hands.get(bus.port, ()):
            self.bus_stats[h] = bus.stats

    def _glove_figures(self, h: str, glove: Any) -> None:
        self.glove_stats[h] = glove.stats()

    # -- the summary --------------------------------------------------------------------
    def _result(self, error: HandrigError | None) -> LiveResult:
        parts = self.parts
        hands: dict[str, dict[str, Any]] = {}
        for h in HANDS:
            side = parts.sides[h]
            stats = self.stats[h]
            outs = app.outputs_summary(self.outputs[h], stats.duration_s)
            s = app.summary_dict(stats, self.bus_stats.get(h), self.glove_stats.get(h),
                                 None, outputs=outs,
                                 clamped=app.clamped_joints(side.pipeline),
                                 ease_s=self.ease_s[h])
            glove = (self.opts.glove if h == "ri" else self.opts.glove_left) or ""
            s["clamp_advice"] = clamp_advice(
                s, glove.removeprefix("replay:") if glove.startswith("replay:") else "",
                tuple(side.expander.controls), side.expander.training_range())
            s["glove_source"] = glove
            hands[HAND_NAMES[h]] = s
        offs = list(self.torque_off.values())
        torque_off = (None if not offs or None in offs else all(bool(v) for v in offs))
        summary = dict(hands["right"])
        summary["torque_off"] = torque_off
        for s in hands.values():
            s["torque_off"] = torque_off
        summary["hands"] = hands
        summary["buses"] = "two" if parts.two_buses else "one"
        summary["simulated_bus"] = any(o.emulator is not None for o in self.opened)
        if self.opts.show:
            summary["show"] = self.opts.show
        if self.signals.received:
            summary["signals"] = self.signals.received
        if error is not None:
            summary["error"] = str(error)
        joints = tuple(s.joint for h in HANDS for s in parts.sides[h].rig_config.servos)
        return LiveResult(summary, self.snapshots, joints,
                          "".join(o.emulator_output() for o in self.opened), error,
                          self.started, self.snapshot_times_s)

    def _snapshots(self, every: int) -> Callable[[float, np.ndarray], None]:
        """An output for the right hand's loop: every ``every`` frames, both hands'
        present positions (right then left, the order of the result's joint names)."""
        counter = [0]

        def snap(t_s: float, pose: np.ndarray) -> None:
            counter[0] += 1
            states = [self.rigs[h].last_state for h in HANDS]
            if counter[0] % every == 0 and all(st is not None for st in states):
                self.snapshots.append(np.concatenate(
                    [np.asarray(st.positions_deg) for st in states if st is not None]))
                self.snapshot_times_s.append(float(t_s))
        return snap


def _close_take(take: Any, what: str, log: Callable[[str], None]) -> None:
    log(f"{what}: {take.close()}")
