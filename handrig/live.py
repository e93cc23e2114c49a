"""One live session: devices opened, torque on, the loop run, torque off, figures out.

Shared by ``handrig run`` and ``handrig demo``. Opens the glove and the servo bus
(starting ``handrig sim-bus`` when the bus is ``"sim"``), commissions the
servos, runs :class:`~handrig.rig.Rig` inside the bus's torque context, and
checks afterwards, by reading every servo's Torque Enable, that torque is off.
"""

from __future__ import annotations

import contextlib
import gc
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from types import FrameType
from typing import Any

import numpy as np

from handrig.app import RigParts, open_glove, port_process, summary_dict
from handrig.clock import Clock, MonotonicClock
from handrig.errors import DeviceError, HandrigError, SafetyStop
from handrig.glove import GloveSource
from handrig.realtime import pinned_loop, realtime_priority
from handrig.rig import Rig
from handrig.rigconfig import RigConfig
from handrig.servo import DynamixelBus
from handrig.servo.dynamixel import ReadFields, cycle_bytes, wire_time_s
from handrig.servo.registers import Reg


@dataclass
class LiveOptions:
    glove: str | None = None  # PORT, opengloves:PORT, replay:FILE (None: glove.toml)
    bus: str | None = None  # PORT or "sim" (None: rig.toml)
    frames: int | None = None
    duration_s: float | None = None
    wire_timing: bool = True  # for the simulated bus
    viewer: bool = False
    vmc: str | None = None
    record: str | None = None
    panel: bool = False
    sim_faults: str = ""
    snapshot_every: int = 0  # keep present positions every N frames (for rendering)
    verbose: bool = False  # log every commissioning step
    profile: bool = False  # record per-stage times of the critical path (bench_rig)
    log: Callable[[str], None] = field(default=lambda text: print(text, file=sys.stderr))


@dataclass
class LiveResult:
    summary: dict[str, Any]
    snapshots: list[np.ndarray]
    joint_names: tuple[str, ...]
    sim_output: str = ""


def read_fields_for(rig: RigConfig) -> ReadFields:
    """What the loop reads back: position, velocity and current when a goal write plus that
    read fit in 70 % of a cycle on the wire, else position only (e.g. 20 servos at 1 Mbps
    and 200 Hz: 4.4 ms of wire for the full read, 3.2 ms for positions, in a 5 ms cycle)."""
    n, period = len(rig.servos), 1.0 / rig.loop.rate_hz
    full = wire_time_s(cycle_bytes(n, data_len=10), rig.bus.baud)
    return "motion" if full <= 0.7 * period else "position"


def torque_is_off(bus: DynamixelBus) -> bool | None:
    """Read Torque Enable back from every servo: True if all are off, None if unreadable."""
    try:
        return all(bus.read_register(i, Reg.TORQUE_ENABLE) == 0 for i in range(bus.n_servos))
    except HandrigError:
        return None


@contextlib.contextmanager
def _sigterm_unwinds() -> Iterator[None]:
    """SIGTERM before torque is on (opening, commissioning) unwinds like Ctrl-C, so the
    emulator subprocesses and ptys are closed; inside ``bus.torque()`` the bus's own
    handler takes over (ease to relaxed, then torque off)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        raise SafetyStop("SIGTERM received before the rig started: stopped, torque was off")

    old = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def run_live(parts: RigParts, opts: LiveOptions, clock: Clock | None = None) -> LiveResult:
    """Run the rig once with ``parts`` and ``opts``; returns the summary figures."""
    with _sigterm_unwinds():
        return _run_live(parts, opts, clock)


def _run_live(parts: RigParts, opts: LiveOptions, clock: Clock | None) -> LiveResult:
    clock = clock or MonotonicClock()
    rig_cfg = parts.rig_config
    bus_spec = opts.bus or rig_cfg.bus.port
    snapshots: list[np.ndarray] = []
    sim_proc = None
    with contextlib.ExitStack() as stack:
        if bus_spec == "sim":
            argv = ["sim-bus", "--rig", str(parts.rig_file)]
            if opts.wire_timing:
                argv.append("--wire-timing")
            if opts.viewer:
                argv.append("--viewer")
            if opts.sim_faults:
                argv += ["--faults", opts.sim_faults]
            sim_proc, bus_port = stack.enter_context(
                port_process(argv, "the simulated servo bus (handrig sim-bus)"))
            opts.log(f"simulated servo bus (MuJoCo puppet) on {bus_port}")
        else:
            bus_port = bus_spec
        glove: GloveSource = open_glove(opts.glove, parts.glove_config, clock)
        stack.enter_context(glove)
        read_fields = read_fields_for(rig_cfg)
        # No reply poll: the loop reads the servos once every few 5 ms cycles, where the
        # tens of microseconds a poll saves do not matter, and a SCHED_FIFO thread that
        # polls holds back the kernel worker delivering the reply (and the glove's
        # bytes) whenever that worker is queued on the loop's CPU (seen with ftrace).
        bus = DynamixelBus(bus_port, rig_cfg, clock=clock, read_fields=read_fields, spin_s=0.0)
        stack.callback(bus.close)
        bus.connect()
        if opts.verbose:
            for line in bus.commissioning:
                opts.log(line)
        else:
            opts.log(f"servo bus {bus_port}: {len(rig_cfg.servos)} servos commissioned "
                     f"({len(bus.commissioning)} settings checked or changed)")

        outputs: list[Callable[[float, np.ndarray], None]] = []
        if opts.vmc:
            from handrig.outputs.vmc import VmcSender, parse_host_port

            host, port = parse_host_port(opts.vmc)
            vmc = VmcSender(host, port, clock=clock)
            stack.callback(vmc.close)
            outputs.append(vmc)
        if opts.record:
            from handrig.outputs.recorder import Recorder

            recorder = Recorder(opts.record, rate_hz=rig_cfg.loop.rate_hz)
            stack.callback(lambda: opts.log(f"recorded performance: {recorder.close()}"))
            outputs.append(recorder)

        rig = Rig(
            glove, bus, parts.pipeline, clock,
            controls_from_raw=parts.controls, orientation=parts.orientation,
            rate_hz=rig_cfg.loop.rate_hz, read_every=rig_cfg.bus.read_every,
            glove_timeout_s=rig_cfg.loop.glove_timeout_s,
            relax_time_s=rig_cfg.loop.relax_time_s, outputs=outputs, log=opts.log,
            profile=opts.profile,
        )
        if opts.snapshot_every > 0:
            every = opts.snapshot_every
            counter = [0]

            def snap(t_s: float, pose: np.ndarray) -> None:
                counter[0] += 1
                state = rig.last_state
                if counter[0] % every == 0 and state is not None:
                    snapshots.append(np.array(state.positions_deg))
            rig.outputs = (*rig.outputs, snap)

        error: HandrigError | None = None
        rig.prepare()  # the garbage collected before torque (and its watchdog) goes on
        stack.callback(gc.unfreeze)  # also when torque-on fails and the loop never runs
        with bus.torque(on_signal=lambda name: rig.request_stop(f"{name} received")):
            # the Rig starts from bus.last_goals_deg: where torque-on holds every servo
            panel = contextlib.nullcontext()
            if opts.panel:
                from handrig.panel import LivePanel

                panel = LivePanel(rig)  # type: ignore[assignment]
            try:
                with (panel, pinned_loop(rig_cfg.loop.pin_cpu, opts.log),
                      realtime_priority(rig_cfg.loop.realtime_priority, opts.log)):
                    rig.run(frames=opts.frames, duration_s=opts.duration_s)
            except DeviceError as exc:
                error = exc
        off = torque_is_off(bus)
        summary = summary_dict(rig, bus.stats, glove.stats(), off)
        if rig.stage_times:
            t = np.diff(np.array(rig.stage_times), axis=1) * 1e6
            names = ("read+decode", "calibrate+filter", "orientation", "targets", "write")
            summary["stages_us"] = {
                name: {"p50": round(float(np.percentile(t[:, i], 50)), 1),
                       "p99": round(float(np.percentile(t[:, i], 99)), 1)}
                for i, name in enumerate(names)}
        if error is not None:
            summary["error"] = str(error)
    sim_output = ""
    if sim_proc is not None and sim_proc.stdout is not None:
        with contextlib.suppress(Exception):
            sim_output = sim_proc.stdout.read() or ""
    return LiveResult(summary, snapshots, tuple(s.joint for s in rig_cfg.servos), sim_output)


def format_summary(summary: dict[str, Any]) -> str:
    """The human-readable summary of a run."""
    lat = summary["latency_us"]
    glove = summary.get("glove", {})
    bus = summary.get("bus", {})
    faults = {k: v for k, v in bus.items()
              if v and any(w in k for w in ("timeout", "crc", "error", "retr", "fault", "stale",
                                            "skipped"))}
    lines = [
        f"frames            {summary['frames']} in {summary['duration_s']} s "
        f"({summary['rate_hz']} Hz, jitter {summary['jitter_us']} us)",
        f"latency           p50 {lat['p50']} us, p99 {lat['p99']} us, max {lat['max']} us "
        "(glove frame read -> Sync Write handed to the OS)",
        f"overruns          {summary['overruns']} (max {summary['overrun_max_us']} us late, "
        f"{summary['missed_cycles']} cycles missed)",
        f"limit clamps      {summary['limit_clamps']} servo targets held at a joint limit "
        f"(end stop), {summary['pose_clamps']} values of the full two-hand pose; "
        f"{summary['bus_clamps']} goals clamped by the driver; slew-limited "
        f"{summary['slew_limited']}; non-finite targets held {summary['nonfinite_targets']}",
        f"glove             {glove.get('frames_ok', '-')} frames ok, "
        f"{glove.get('crc_errors', 0)} CRC errors, {glove.get('decode_errors', 0)} other "
        f"errors, {glove.get('resyncs', 0)} resyncs, used {glove.get('frames_used', '-')}",
        f"faults            {faults if faults else 'none'}",
        f"tracking          rms {summary['tracking_rms_deg']} deg, max "
        f"{summary['tracking_max_deg']} deg (present vs goal, {summary['reads']} reads, "
        f"{summary['stale_reads']} with stale servos)",
        f"safety            {summary['relax_events']} relax events, e-stop "
        f"{'pressed' if summary['estop'] else 'not pressed'}, stopped: {summary['stop_reason']}",
        f"torque off        {summary['torque_off']}",
    ]
    if "error" in summary:
        lines.append(f"error             {summary['error']}")
    return "\n".join(lines)
