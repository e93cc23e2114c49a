"""The one factory: concrete devices and the pipeline built from config files.

Everything else takes its dependencies as arguments; only this module (and the
commands that call it) decide which glove, bus, map and grid a run uses.
``sim`` is imported only when the user asks for the simulated rig (``--bus sim``).
"""

from __future__ import annotations

import contextlib
import math
import selectors
import subprocess
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from handrig.clock import Clock
from handrig.config import CONFIG_DIR, load_joint_limits
from handrig.errors import ConfigError, DeviceError
from handrig.expand import Expander
from handrig.glove import GloveSample, GloveSource, ReplayGlove, SerialGlove
from handrig.glove_calibration import GloveConfig, GloveControls, load_glove_config
from handrig.glove_recording import read_glove_recording
from handrig.orientation import ForearmOrientation
from handrig.pipeline import PosePipeline
from handrig.realtime import helper_env
from handrig.rigconfig import RigConfig, load_rig_config
from handrig.sag import SagGrid

FloatArray = NDArray[np.float64]


def _resolve(base: Path, value: str, default: Path) -> Path:
    if not value:
        return default
    p = Path(value)
    return p if p.is_absolute() else base / p


@dataclass
class RigParts:
    """The configured, device-free parts of a run."""

    rig_config: RigConfig
    rig_file: Path
    glove_config: GloveConfig
    expander: Expander
    sag: SagGrid
    pipeline: PosePipeline
    controls: GloveControls
    orientation: ForearmAngles


class ForearmAngles:
    """Glove sample -> (inclination, rotation) of the forearm, in degrees.

    Uses the sample's IMU quaternion through :class:`ForearmOrientation` (mount and
    convention from glove.toml); a glove without an IMU (OpenGloves), or a sample
    whose quaternion was rejected, gets the last good orientation, or the fixed
    ``[forearm]`` of glove.toml before any.
    """

    def __init__(self, cfg: GloveConfig) -> None:
        imu = cfg.imu
        self.orientation = ForearmOrientation(
            Rotation.from_quat(np.asarray(imu.mount_xyzw, dtype=np.float64)),
            scalar_first=imu.order == "wxyz",
            world=imu.world,
        )
        self.last = (cfg.forearm.inclination_deg, cfg.forearm.rotation_deg)
        self.fixed = cfg.glove.format == "opengloves"

    def __call__(self, sample: GloveSample) -> tuple[float, float]:
        if self.fixed or sample.quat is None:
            return self.last
        inclination, rotation, ok = self.orientation.update(sample.quat)
        if ok:
            self.last = (inclination, rotation)
        return self.last


def build_parts(rig_file: str | Path | None = None, glove_file: str | Path | None = None
                ) -> RigParts:
    """Load the rig, glove, map and grid configs and build the pose pipeline."""
    rig_path = Path(rig_file) if rig_file else CONFIG_DIR / "rig.toml"
    rig = load_rig_config(rig_path)
    base = rig_path.resolve().parent
    loop = rig.loop
    glove_path = Path(glove_file) if glove_file else _resolve(
        base, loop.glove, CONFIG_DIR / "glove.toml")
    glove_cfg = load_glove_config(glove_path)
    limits = load_joint_limits()
    expander = Expander.from_file(_resolve(base, loop.map, CONFIG_DIR / "maps" / "default.toml"),
                                  limits)
    sag = SagGrid.load(_resolve(base, loop.sag_grid, CONFIG_DIR / "sag_grid.npz"))
    pipeline = PosePipeline(
        expander, sag, [s.joint for s in rig.servos],
        servo_limits_deg=np.array([[s.min_deg, s.max_deg] for s in rig.servos]),
        limits=limits, slew_deg_s=loop.slew_deg_s, sag_gain=loop.sag_gain,
        left_hand=loop.left_hand, control_means_deg=expander.control_means_deg,
        left_forearm_deg=loop.left_forearm_deg,
    )
    controls = GloveControls.from_config(glove_cfg, expander.controls)
    return RigParts(rig, rig_path, glove_cfg, expander, sag, pipeline, controls,
                    ForearmAngles(glove_cfg))


def open_glove(spec: str | None, cfg: GloveConfig, clock: Clock) -> GloveSource:
    """``PORT``, ``opengloves:PORT`` or ``replay:FILE`` (None: the port in glove.toml)."""
    if spec is None or spec == "":
        if not cfg.glove.port:
            raise ConfigError(
                "no glove port given", key="glove.port",
                allowed="pass --glove PORT (or replay:FILE) or set [glove] port in glove.toml",
            )
        spec = cfg.glove.port if cfg.glove.format == "frames" else f"opengloves:{cfg.glove.port}"
    if spec.startswith("replay:"):
        return ReplayGlove(read_glove_recording(spec.removeprefix("replay:")), clock)
    if spec.startswith("opengloves:"):
        return SerialGlove(spec.removeprefix("opengloves:"), "opengloves", clock=clock,
                           baud=cfg.glove.baud, analog_max=cfg.glove.analog_max,
                           estop_letter=cfg.glove.estop_letter, reader="poll")
    # reader="poll": the loop itself reads the port without blocking, so a frame is
    # handled in the cycle that reads it (no reader thread competing for the GIL).
    return SerialGlove(spec, "frames", clock=clock, baud=cfg.glove.baud, reader="poll")


@contextlib.contextmanager
def port_process(argv: Sequence[str], what: str, timeout_s: float = 30.0
                 ) -> Iterator[tuple[subprocess.Popen[str], str]]:
    """Start a handrig subcommand that prints ``port: PATH`` first; stop it on exit.

    Yields the process and the port path. The process gets SIGTERM on exit and is
    waited for, so the emulators shut down cleanly.
    """
    cmd = [sys.executable, "-m", "handrig.cli", *argv]
    env = helper_env()  # off the loop's CPU
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env)
    try:
        assert proc.stdout is not None
        sel = selectors.DefaultSelector()
        sel.register(proc.stdout, selectors.EVENT_READ)
        line = ""
        if sel.select(timeout_s):
            line = proc.stdout.readline().strip()
        sel.close()
        if not line.startswith("port: "):
            proc.kill()
            _, err = proc.communicate(timeout=5)
            raise DeviceError(
                f"{what} did not start ({' '.join(argv)}): "
                f"{(line + ' ' + err).strip()[-400:] or 'no output'}"
            )
        yield proc, line.removeprefix("port: ")
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def stop_process(proc: subprocess.Popen[str]) -> str:
    """SIGTERM a port process, wait, and return what it printed after its port line."""
    if proc.poll() is None:
        proc.terminate()
    try:
        out, err = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
    return (out or "") + (err or "")


def summary_dict(rig: Any, bus_stats: Any, glove_stats: Any, torque_off: bool | None
                 ) -> dict[str, Any]:
    """The run's figures as one JSON-able object (the keys ``handrig demo --json`` promises)."""
    s = rig.stats
    def num(x: float, nd: int = 3) -> float | None:
        return None if x is None or not math.isfinite(x) else round(float(x), nd)
    out: dict[str, Any] = {
        "frames": s.frames,
        "duration_s": num(s.duration_s),
        "rate_hz": num(s.rate_hz, 2),
        "jitter_us": num(s.jitter_us, 1),
        "latency_us": {"p50": num(s.latency_us(50), 1), "p99": num(s.latency_us(99), 1),
                       "max": num(s.latency_us(100), 1), "samples": len(s.latencies_s)},
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
        "estop": s.estop,
        "stop_reason": s.stop_reason,
        "events": list(s.events),
        "torque_off": torque_off,
    }
    if glove_stats is not None:
        out["glove"] = {
            "frames_ok": glove_stats.frames_ok, "crc_errors": glove_stats.crc_errors,
            "decode_errors": glove_stats.decode_errors, "resyncs": glove_stats.resyncs,
            "seq_gaps": glove_stats.seq_gaps, "frames_used": s.glove_samples,
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
    return out
