"""The one factory: concrete devices, outputs and the pipeline built from config files.

Everything else takes its dependencies as arguments; only this module (and the
commands that call it) decide which glove, bus, map, grid and outputs a run uses.
The simulated rig's emulators run as subprocesses (``handrig sim-bus``,
``handrig sim-glove``) started through :mod:`handrig.app.port_processes`, each in
its own session so that a Ctrl-C in the terminal reaches the rig alone: the rig
eases, turns torque off, and only then stops them. In-process simulator parts
come through :mod:`handrig.app.simulator`.
"""

from __future__ import annotations

import contextlib
import math
import subprocess
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from firmware_protocol.glove import FLAG_IMU_ABSENT
from handrig.app import robots as robotrig
from handrig.app.port_processes import (  # noqa: F401 (stop_process: named here as before)
    SIM_BUS,
    StartedEmulators,
    port_process,
    sim_bus_argv,
    stop_process,
)
from handrig.clock import Clock
from handrig.config.loading import CONFIG_DIR, load_joint_limits
from handrig.config.paths import config_file
from handrig.config.rig import SIM_PORT, RigConfig, require_port
from handrig.devices.glove import GloveSample, GloveSource, GloveStats, ReplayGlove, SerialGlove
from handrig.devices.glove_calibration import (
    GloveConfig,
    GloveControls,
    default_glove_path,
    load_glove_config,
)
from handrig.devices.glove_recording import check_channels, read_glove_recording
from handrig.devices.servo import DynamixelBus
from handrig.devices.servo.dynamixel import ReadFields, cycle_bytes, wire_time_s
from handrig.errors import ConfigError
from handrig.loop.ports import ControlsFromRaw, OrientationLike
from handrig.loop.rig import Rig
from handrig.loop.stats import RunStats
from handrig.outputs.base import Output
from handrig.pose.expand import Expander
from handrig.pose.orientation import ForearmOrientation
from handrig.pose.pipeline import PosePipeline
from handrig.pose.sag import SagGrid, default_grid_path

FloatArray = NDArray[np.float64]


def _resolve(base: Path, value: str, default: Path, *, rig_file: Path | None = None,
             key: str = "") -> Path:
    """``value`` of the rig file's ``key`` as a path (relative: to the rig file's folder
    ``base``), ``default`` when empty; a named file that is not there is a ConfigError
    saying which key pointed there."""
    if not value:
        return default
    p = Path(value)
    p = p if p.is_absolute() else base / p
    if rig_file is not None and not p.is_file():
        relative = ("" if Path(value).is_absolute()
                    else f" (relative to the rig file's folder {base})")
        raise ConfigError(f"no such file: {p}{relative}", file=str(rig_file), key=key,
                          value=value, allowed="an existing file, or empty for the default")
    return p


@dataclass
class RigParts:
    """The configured, device-free parts of a run."""

    rig_config: RigConfig
    rig_file: Path
    glove_config: GloveConfig
    expander: Expander
    sag: SagGrid
    pipeline: PosePipeline
    controls: ControlsFromRaw  # the glove's GloveControls (a take played: its pose; a
    # hand of two gloves: its glove's into the shared vector, hands.SideControls)
    orientation: OrientationLike  # the glove's ForearmAngles (a take played: fixed)
    glove_file: Path | None = None  # where glove_config was read from
    hand: str | None = None  # one hand's servos of a two-hand rig ("ri", "le"); None: all


class ForearmAngles:
    """Glove sample -> (inclination, rotation) of the forearm, in degrees.

    Uses the sample's IMU quaternion through :class:`ForearmOrientation` (mount and
    convention from glove.toml); a glove without an IMU (OpenGloves), or a sample
    whose quaternion was rejected, gets the last good orientation, or the fixed
    ``[forearm]`` of glove.toml before any. A frame flagged "IMU absent" (the glove's
    IMU is gone) gets the fixed ``[forearm]``: the last good orientation may be long
    stale.
    """

    def __init__(self, cfg: GloveConfig, hand: Literal["ri", "le"] = "ri") -> None:
        imu = cfg.imu
        self.orientation = ForearmOrientation(
            Rotation.from_quat(np.asarray(imu.mount_xyzw, dtype=np.float64)),
            scalar_first=imu.order == "wxyz",
            world=imu.world, hand=hand,
        )
        self.configured = (cfg.forearm.inclination_deg, cfg.forearm.rotation_deg)
        self.last = self.configured
        self.fixed = cfg.glove.format == "opengloves"

    def __call__(self, sample: GloveSample) -> tuple[float, float]:
        if sample.quat is None and sample.status & FLAG_IMU_ABSENT:
            self.last = self.configured
        if self.fixed or sample.quat is None:
            return self.last
        inclination, rotation, ok = self.orientation.update(sample.quat)
        if ok:
            self.last = (inclination, rotation)
        return self.last


def build_parts(rig_file: str | Path | None = None, glove_file: str | Path | None = None,
                *, map_file: str | Path | None = None, grid_file: str | Path | None = None
                ) -> RigParts:
    """Load the rig, glove, map and grid configs and build the pose pipeline.

    ``rig_file``: a rig file or a preset name (``"leap"``: ``config/rigs/leap.toml``);
    None is the user's ``rig.toml`` (:func:`handrig.config.paths.config_file`), else the
    installed ``config/rig.toml``. A robot rig's pipeline ends in its retarget table, with
    the rig's effective sag gain (off unless ``[robot].sag`` is true). ``map_file`` and
    ``grid_file`` (a show file's) stand in for the rig file's ``[loop] map`` and
    ``sag_grid``."""
    rig_path = robotrig.rig_path(rig_file) if rig_file else config_file("rig.toml")
    rig = robotrig.load_rig(rig_path)
    retarget = (robotrig.robot_retarget(rig) if isinstance(rig, robotrig.RobotRigConfig)
                else None)
    base = rig_path.resolve().parent
    loop = rig.loop
    glove_path = Path(glove_file) if glove_file else _resolve(
        base, loop.glove, default_glove_path(), rig_file=rig_path, key="loop.glove")
    glove_cfg = load_glove_config(glove_path)
    limits = load_joint_limits()
    expander = Expander.from_file(Path(map_file) if map_file else _resolve(
        base, loop.map, CONFIG_DIR / "maps" / "default.toml", rig_file=rig_path,
        key="loop.map"), limits)
    sag = SagGrid.load(Path(grid_file) if grid_file else _resolve(
        base, loop.sag_grid, default_grid_path(), rig_file=rig_path, key="loop.sag_grid"))
    pipeline = PosePipeline(
        expander, sag, [s.joint for s in rig.servos],
        servo_limits_deg=np.array([[s.min_deg, s.max_deg] for s in rig.servos]),
        limits=limits, slew_deg_s=loop.slew_deg_s, sag_gain=rig.effective_sag_gain,
        left_hand=loop.left_hand, control_means_deg=expander.control_means_deg,
        left_forearm_deg=loop.left_forearm_deg, retarget=retarget,
    )
    controls = GloveControls.from_config(glove_cfg, expander.controls)
    return RigParts(rig, rig_path, glove_cfg, expander, sag, pipeline, controls,
                    ForearmAngles(glove_cfg), glove_path)


def robot_model(rig: RigConfig) -> str | None:
    """The MJCF model a robot rig drives (``[robot].model``, absolute); None for a human rig."""
    return rig.robot.model if isinstance(rig, robotrig.RobotRigConfig) and rig.robot else None


REPLAY_SUFFIXES = (".csv", ".txt")  # what a glove recording is usually called


def glove_spec(spec: str | None, cfg: GloveConfig, glove_file: Path | None = None) -> str:
    """The glove a run opens: ``spec`` (``--glove``), else the port in the glove file;
    checked without opening anything. ConfigError naming ``--glove`` or the glove
    file's ``glove.port``, with the fix: a recording given as a port (it would fail
    with the terminal's ``Inappropriate ioctl for device``), a port or recording that
    is not there, no port at all."""
    if spec is None or spec == "":
        if not cfg.glove.port:
            raise ConfigError(
                "no glove port given", key="glove.port",
                file=str(glove_file) if glove_file is not None else "glove.toml",
                allowed="pass --glove PORT (or replay:FILE.csv), or set [glove] port "
                "in this file")
        spec = cfg.glove.port if cfg.glove.format == "frames" else f"opengloves:{cfg.glove.port}"
    if spec.startswith("replay:"):
        path = Path(spec.removeprefix("replay:"))
        if not path.is_file():
            raise ConfigError(f"glove recording not found: {path}", key="--glove", value=spec,
                              allowed="replay:FILE with an existing glove take "
                              "(`handrig record glove TAKE.csv` or `handrig run "
                              "--record-glove TAKE.csv` make one)")
        return spec
    port = Path(spec.removeprefix("opengloves:"))
    if port.is_file() or (port.suffix.lower() in REPLAY_SUFFIXES and not port.exists()):
        raise ConfigError("a file, not a serial port", key="--glove", value=spec,
                          allowed=f"a serial port such as /dev/ttyUSB0; to play a "
                          f"recording pass --glove replay:{port}")
    if port.is_absolute() and not port.exists():
        raise ConfigError(f"no such port: {port}", key="--glove", value=spec,
                          allowed="the glove's serial port (plugged in? `ls /dev/ttyUSB* "
                          "/dev/ttyACM*`), or replay:FILE.csv")
    return spec


def check_outputs(vmc: str | None, record: str | None) -> None:
    """``--vmc`` and ``--record`` checked before any device is opened: ConfigError naming
    the flag (a VMC target without its port, a recording suffix that is neither .csv nor
    .bvh)."""
    if vmc:
        from handrig.outputs.vmc import DEFAULT_PORT, parse_host_port

        if ":" not in vmc:
            raise ConfigError("no port given", key="--vmc", value=vmc,
                              allowed=f"HOST:PORT, e.g. {vmc}:{DEFAULT_PORT} (VMC's usual port)")
        parse_host_port(vmc)
    if record:
        suffix = Path(record).suffix.lower()
        if suffix not in (".csv", ".bvh"):
            raise ConfigError(f"unknown recording suffix {suffix or '(none)'!r}", key="--record",
                              value=record, allowed="a file name ending in .csv or .bvh")
        from handrig.outputs.recorder import check_new_take

        check_new_take(record)  # a take is never replaced: refused before the bus opens


def open_glove(spec: str | None, cfg: GloveConfig, clock: Clock,
               glove_file: Path | None = None) -> GloveSource:
    """``PORT``, ``opengloves:PORT`` or ``replay:FILE`` (None: the port in glove.toml),
    checked first (:func:`glove_spec`)."""
    spec = glove_spec(spec, cfg, glove_file)
    needed = max(ch.raw_index() for ch in cfg.channels) + 1
    if spec.startswith("replay:"):
        path = spec.removeprefix("replay:")
        rec = read_glove_recording(path)
        check_channels(rec, needed, path, glove_file)  # a take of another glove
        return ReplayGlove(rec, clock)
    if spec.startswith("opengloves:"):
        return SerialGlove(spec.removeprefix("opengloves:"), "opengloves", clock=clock,
                           baud=cfg.glove.baud, analog_max=cfg.glove.analog_max,
                           estop_letter=cfg.glove.estop_letter, reader="poll")
    # reader="poll": the loop itself reads the port without blocking, so a frame is
    # handled in the cycle that reads it (no reader thread competing for the GIL).
    # a frame with fewer raw channels than the calibration reads is never settled on
    names = [""] * needed
    for ch in cfg.channels:
        names[ch.raw_index()] = names[ch.raw_index()] or ch.curve
    return SerialGlove(spec, "frames", clock=clock, baud=cfg.glove.baud, reader="poll",
                       min_channels=needed, channel_names=names)


def cycle_rate_hz(rig: RigConfig, glove_rate_hz: float) -> float:
    """Cycles a second the loop runs at: the glove's nominal frame rate in mode "glove"
    (held to the ceiling), ``[loop] rate_hz`` in mode "fixed"."""
    if rig.loop.mode == "fixed":
        return rig.loop.rate_hz
    return min(glove_rate_hz, rig.loop.ceiling_hz)


def read_fields_for(rig: RigConfig, glove_rate_hz: float) -> ReadFields:
    """What the loop reads back: position, velocity and current when a goal write plus that
    read fit in 70 % of a cycle on the wire, else position only (e.g. 20 servos at 1 Mbps
    and 200 Hz: 4.4 ms of wire for the full read, 3.2 ms for positions, in a 5 ms cycle).
    The cycle is the loop's (:func:`cycle_rate_hz`), not ``[loop] rate_hz`` in mode glove."""
    n, period = len(rig.servos), 1.0 / cycle_rate_hz(rig, glove_rate_hz)
    full = wire_time_s(cycle_bytes(n, data_len=10), rig.bus.baud)
    return "motion" if full <= 0.7 * period else "position"


@dataclass
class OpenedBus:
    """A servo bus the factory opened (not yet connected): the driver, its port, and the
    emulator process behind it when the bus is simulated."""

    bus: DynamixelBus
    port: str
    emulator: subprocess.Popen[str] | None = None

    def emulator_output(self) -> str:
        """What the emulator printed after its port line (read once it has stopped)."""
        if self.emulator is None or self.emulator.stdout is None:
            return ""
        try:
            return self.emulator.stdout.read() or ""
        except (OSError, ValueError):
            return ""


@contextlib.contextmanager
def servo_bus(spec: str | None, parts: RigParts, clock: Clock, *, wire_timing: bool = True,
              viewer: bool = False, faults: str = "",
              log: Callable[[str], None] = print,
              started: StartedEmulators | None = None) -> Iterator[OpenedBus]:
    """The servo bus on ``spec`` (a port, ``"sim"``, None: rig.toml's port); closed on exit
    (torque off if still on). ``"sim"`` starts ``handrig sim-bus`` (the MuJoCo puppet,
    ``wire_timing``, ``viewer``, ``faults``) first, or takes the one ``started`` holds
    for these arguments (:func:`~handrig.app.port_processes.sim_bus_argv`), and stops it
    after the bus is closed."""
    rig_cfg = parts.rig_config
    bus_spec = require_port(spec or rig_cfg.bus.port, parts.rig_file,
                            flag="--bus-left" if parts.hand == "le" else "--port")
    with contextlib.ExitStack() as stack:
        proc: subprocess.Popen[str] | None = None
        if bus_spec == SIM_PORT:
            argv = sim_bus_argv(parts.rig_file, parts.hand, wire_timing=wire_timing,
                                viewer=viewer, faults=faults)
            emulator = started.take(argv) if started is not None else None
            if emulator is None:
                proc, port = stack.enter_context(port_process(argv, SIM_BUS))
            else:
                stack.enter_context(emulator)
                proc, port = emulator.proc, emulator.port()
            log(f"SIMULATED servo bus ({SIM_PORT!r}: the emulated servos and MuJoCo puppet "
                f"on {port}); no hardware is driven")
        else:
            port = bus_spec
        # No reply poll (spin_s 0): the loop reads the servos once every few cycles, where
        # the tens of microseconds a poll saves do not matter, and a SCHED_FIFO thread
        # that polls holds back the kernel worker delivering the reply (and the glove's
        # bytes) whenever that worker is queued on the loop's CPU.
        fields = read_fields_for(rig_cfg, parts.glove_config.glove.rate_hz)
        bus = DynamixelBus(port, rig_cfg, clock=clock, read_fields=fields,
                           spin_s=0.0, emulated=proc is not None,
                           missing_ok=rig_cfg.silence.action == "continue")
        stack.callback(bus.close)
        yield OpenedBus(bus, port, proc)


def outputs(stack: contextlib.ExitStack, rig_cfg: RigConfig, clock: Clock, *,
            vmc: str | None = None, record: str | None = None,
            log: Callable[[str], None] = print, glove_rate_hz: float | None = None,
            record_rate_hz: float | None = None
            ) -> list[Callable[[float, FloatArray], None]]:
    """The outputs a run feeds the full pose to: a VMC sender (``HOST:PORT``), a
    recorder (``.csv`` or ``.bvh``). Each is closed when ``stack`` unwinds. A BVH take
    is written at ``record_rate_hz`` if given (``--record-rate``), else at the glove's
    nominal rate (``glove_rate_hz``, ``[glove] rate_hz``) when the loop follows the
    glove, at ``[loop] rate_hz`` in mode "fixed"."""
    out: list[Callable[[float, FloatArray], None]] = []
    if vmc:
        from handrig.outputs.vmc import VmcSender, parse_host_port

        host, port = parse_host_port(vmc)
        sender = VmcSender(host, port, clock=clock)
        stack.callback(sender.close)
        out.append(sender)
    if record:
        from handrig.outputs.recorder import Recorder

        rate_hz = rig_cfg.loop.rate_hz
        if rig_cfg.loop.mode == "glove" and glove_rate_hz:
            rate_hz = glove_rate_hz
        if record_rate_hz:
            rate_hz = record_rate_hz
        recorder = Recorder(record, rate_hz=rate_hz, log=log)
        stack.callback(lambda: log(f"recorded performance: {recorder.close()}"))
        out.append(recorder)
    return out


def build_rig(parts: RigParts, glove: Any, bus: Any, clock: Clock, *,
              outputs: Sequence[Callable[[float, FloatArray], None]] = (),
              log: Callable[[str], None] = print, profile: bool = False,
              ease_in: bool = False) -> Rig:
    """The loop on these devices, with the rig file's rates and safety timings
    (:meth:`Rig.from_config`); ``ease_in``: the first frame eases in (a take played)."""
    return Rig.from_config(parts.rig_config, glove, bus, parts.pipeline, clock,
                           controls_from_raw=parts.controls, orientation=parts.orientation,
                           outputs=outputs, log=log, profile=profile, ease_in=ease_in,
                           raw_channels=control_channels(parts.glove_config,
                                                         parts.pipeline.expander.controls))


def control_channels(glove_cfg: GloveConfig, controls: Sequence[str],
                     glove_names: Sequence[str] | None = None) -> tuple[int, ...]:
    """The raw channel driving each of ``controls`` (the glove file's ``[[channels]]``),
    so the telemetry shows each control beside its own channel's count; -1 for a
    control this glove does not drive (its count shows as missing). ``glove_names``:
    the glove file's curve for each control, where it differs (a left glove calibrated
    with the right glove's names)."""
    by_curve = {ch.curve: ch.raw_index() for ch in glove_cfg.channels}
    return tuple(by_curve.get(n, -1) for n in (controls if glove_names is None
                                                else glove_names))


FAULT_WORDS: dict[str, str] = {
    "timeouts": "read timeouts",
    "retries": "read retries",
    "crc_errors": "replies with a bad CRC",
    "malformed": "malformed replies",
    "status_errors": "readings refused by a servo",
    "fallbacks": "fallbacks to plain Sync Read",
    "watchdog_trips": "Bus Watchdog trips",
    "watchdog_gaps": "writes close to the Bus Watchdog",
    "late_replies": "late replies dropped",
    "partial_replies": "Fast Sync Read replies cut short",
    "chain_ends": "reads asking silent servos last",
    "skipped_reads": "reads skipped (no room on the wire)",
    "stale_readings": "stale servo readings",
    "hardware_errors": "servo hardware errors",
    "reboots": "servo reboots",
}
"""Bus counters that are faults, as the summary names them (in this order)."""

TOP_CLAMPED = 3  # joints named in the summary's clamp line


def bus_faults(bus: dict[str, Any]) -> dict[str, int]:
    """The non-zero fault counters of a summary's ``bus`` figures, named in words."""
    return {FAULT_WORDS[k]: int(bus[k]) for k in FAULT_WORDS if bus.get(k)}


def clamped_joints(pipeline: PosePipeline, top: int = TOP_CLAMPED) -> list[dict[str, Any]]:
    """The servo joints whose targets were clamped most often (most first, none at 0)."""
    counts = np.asarray(pipeline.servo_clamps_by_servo, dtype=np.int64)
    joints = tuple(pipeline.servo_joints)
    order: list[int] = np.argsort(-counts, kind="stable")[:top].tolist() if counts.size else []
    return [{"joint": joints[i], "clamps": int(counts[i])} for i in order if counts[i] > 0]


def outputs_summary(outs: Sequence[Any], duration_s: float = 0.0) -> dict[str, Any]:
    """What a run sent besides the servos: ``vmc`` (target, bundles, rate, errors) and
    ``recording`` (path, format, frames, duration, bytes), None when off."""
    out: dict[str, Any] = {"vmc": None, "recording": None}
    for o in outs:
        if not isinstance(o, Output):
            continue
        st = o.status()
        if st.kind == "vmc":
            sent = st.frames_written
            out["vmc"] = {"target": st.address, "bundles_sent": sent,
                          "rate_hz": round(sent / duration_s, 1) if duration_s > 0 else None,
                          "errors": st.errors, "last_error": st.last_error}
        elif st.kind == "recorder":
            out["recording"] = {
                "path": st.path, "format": st.name, "frames": st.frames_written,
                "duration_s": round(st.duration_s, 3), "bytes": st.bytes_written,
                "frames_dropped": st.frames_dropped, "stopped_reason": st.stopped_reason}
        elif st.kind == "glove take":
            out["glove_take"] = {
                "path": st.path, "frames": st.frames_written,
                "duration_s": round(st.duration_s, 3), "bytes": st.bytes_written,
                "frames_dropped": st.frames_dropped, "stopped_reason": st.stopped_reason}
    return out


def summary_dict(stats: RunStats, bus_stats: Any, glove_stats: GloveStats | None,
                 torque_off: bool | None,
                 *, outputs: dict[str, Any] | None = None,
                 clamped: list[dict[str, Any]] | None = None, ease_s: float = 0.0
                 ) -> dict[str, Any]:
    """The run's figures as one JSON-able object (the keys ``handrig demo --json`` promises).

    ``outputs``: :func:`outputs_summary`; ``clamped``: :func:`clamped_joints`;
    ``ease_s``: how long the run eased to the relaxed pose at its end (included in
    ``frames`` and ``duration_s``; 0 when it ended at once)."""
    s = stats

    def num(x: float, nd: int = 3) -> float | None:
        return None if x is None or not math.isfinite(x) else round(float(x), nd)
    out: dict[str, Any] = {
        "frames": s.frames,
        "duration_s": num(s.duration_s),
        "rate_hz": num(s.rate_hz, 2),
        "jitter_us": num(s.jitter_us, 1),
        "latency_us": {"p50": num(s.latency_us(50), 1), "p99": num(s.latency_us(99), 1),
                       "max": num(s.latency_us(100), 1), "samples": s.latency.count},
        "loop_mode": s.loop_mode,
        "compute_us": {"p50": num(s.compute_us(50), 1), "p99": num(s.compute_us(99), 1),
                       "max": num(s.compute_us(100), 1)},
        "writes_per_s": num(s.rate_hz, 2),
        "reads_per_s": num(s.reads / s.duration_s if s.duration_s > 0 else math.nan, 2),
        "writes_delayed_by_reads": s.writes_delayed,
        "cycles_without_frame": s.cycles_without_frame,
        "frames_skipped": s.frames_skipped,
        "frames_in_bursts": s.frames_in_bursts,
        "frames_in_host_stalls": s.frames_in_host_stalls,
        "frames_caught_up": s.frames_caught_up,
        "ceiling_waits": s.ceiling_waits,
        "cpu_per_cycle_us": num(s.cpu_per_cycle_us, 1),
        "overruns": s.overruns,
        "overrun_max_us": num(s.overrun_max_s * 1e6, 1),
        "missed_cycles": s.missed_cycles,
        "limit_clamps": s.servo_clamps,
        "pose_clamps": s.clamps,
        "nonfinite_targets": s.nonfinite,
        "bus_clamps": s.bus_clamps,
        "slew_limited": s.slewed,
        "tracking_rms_deg": num(s.tracking_rms_deg),
        "tracking_max_deg": num(s.tracking_max_deg),
        "reads": s.reads,
        "stale_reads": s.stale_reads,
        "relax_events": s.relax_events,
        "silence": {"silences": s.servo_silences, "held": s.servos_held,
                    "recoveries": s.servo_recoveries, "admitted": s.servos_admitted},
        "heat": {"warnings": s.heat_warnings, "reliefs": s.heat_reliefs,
                 "actions": s.heat_actions, "hottest": s.hottest,
                 "max_c": [num(t, 1) for t in s.max_temperature_c]},
        "resumes": s.resumes,
        "relax_keys": s.relax_keys,
        "estop": s.estop,
        "stop_reason": s.stop_reason,
        "events": list(s.events),
        "events_total": s.events.total,
        "torque_off": torque_off,
        "ease_s": num(ease_s),
        "clamped_joints": list(clamped or []),
        "outputs": outputs if outputs is not None else {"vmc": None, "recording": None},
        "faults": {},
    }
    if glove_stats is not None:
        out["glove"] = {
            "frames_ok": glove_stats.frames_ok, "crc_errors": glove_stats.crc_errors,
            "decode_errors": glove_stats.decode_errors, "resyncs": glove_stats.resyncs,
            "seq_gaps": glove_stats.seq_gaps, "frames_used": s.glove_samples,
            "channel_errors": glove_stats.channel_errors,
            "disconnects": glove_stats.disconnects,
            "reconnects": glove_stats.reconnects,
            "last_outage_s": num(glove_stats.last_outage_s),
        }
    if bus_stats is not None:
        bus: dict[str, Any] = {}
        for k, v in vars(bus_stats).items():
            if k.startswith("_") or k == "n_servos":
                continue
            if isinstance(v, np.ndarray):
                bus[k] = int(v.sum())
            elif isinstance(v, int | float):
                bus[k] = v
        out["bus"] = bus
        out["faults"] = bus_faults(bus)
    return out
