"""The configured, device-free parts of a run: the rig, glove, map and grid files loaded
and checked, the pose pipeline built, the flags checked before any device opens.

:func:`build_parts` is what every run starts from (:mod:`handrig.app.factory` then
opens the devices on these parts). Which rig file a name means is
:func:`handrig.config.rig_files.resolve_rig_file`'s one rule.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from firmware_protocol.glove import FLAG_IMU_ABSENT
from handrig.app.robot_gravity import build_gravity
from handrig.config.loading import CONFIG_DIR, load_joint_limits
from handrig.config.rig import RigConfig
from handrig.config.rig_files import rig_file_path
from handrig.devices.glove import GloveSample
from handrig.devices.glove_calibration import (
    GloveConfig,
    GloveControls,
    default_glove_path,
    load_glove_config,
)
from handrig.errors import ConfigError
from handrig.loop.ports import ControlsFromRaw, OrientationLike
from handrig.pose import robot_rig as robotrig
from handrig.pose.expand import Expander
from handrig.pose.gravity import GravityCompensation
from handrig.pose.orientation import ForearmOrientation
from handrig.pose.pipeline import PosePipeline
from handrig.pose.sag import SagGrid, default_grid_path


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
    map_file: Path | None = None  # where the expander's map was read from
    gravity: GravityCompensation | None = None  # a robot rig's [robot] gravity = true


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
    rig_path = rig_file_path(rig_file)
    rig = robotrig.load_rig(rig_path)
    retarget = (robotrig.robot_retarget(rig) if isinstance(rig, robotrig.RobotRigConfig)
                else None)
    base = rig_path.resolve().parent
    loop = rig.loop
    glove_path = Path(glove_file) if glove_file else _resolve(
        base, loop.glove, default_glove_path(), rig_file=rig_path, key="loop.glove")
    glove_cfg = load_glove_config(glove_path)
    limits = load_joint_limits()
    map_path = Path(map_file) if map_file else _resolve(
        base, loop.map, CONFIG_DIR / "maps" / "default.toml", rig_file=rig_path,
        key="loop.map")
    expander = Expander.from_file(map_path, limits)
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
    gravity = (build_gravity(rig, pipeline.servo_low, pipeline.servo_high)
               if isinstance(rig, robotrig.RobotRigConfig) else None)
    return RigParts(rig, rig_path, glove_cfg, expander, sag, pipeline, controls,
                    ForearmAngles(glove_cfg), glove_path, map_file=map_path, gravity=gravity)


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


def check_outputs(vmc: str | None, record: str | None, openxr: str | None = None) -> None:
    """``--vmc``, ``--openxr`` and ``--record`` checked before any device is opened:
    ConfigError naming the flag (a VMC or OpenXR target without its port, a recording
    suffix that is neither .csv nor .bvh)."""
    if openxr:
        from handrig.outputs.openxr import DEFAULT_PORT as XR_PORT
        from handrig.outputs.openxr import parse_target

        if ":" not in openxr:
            raise ConfigError("no port given", key="--openxr", value=openxr,
                              allowed=f"HOST:PORT, e.g. {openxr}:{XR_PORT}")
        parse_target(openxr)
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
