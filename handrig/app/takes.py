"""Takes on the live rig: a glove take recorded while the show runs, a take played back.

* :func:`open_glove_take`: ``--record-glove TAKE.csv`` (and ``handrig record glove``):
  a :class:`~handrig.outputs.glove_take.GloveTake` tapped onto the glove, so every frame
  the glove sent is stored with its arrival time;
* :func:`load_play_take`: ``handrig play TAKE --bus``: a glove take, or a performance
  (BVH or CSV from ``--record``), read and checked before any device is opened (the file
  named in every complaint: another vocabulary, a different number of curves or channels,
  a truncated file, times going backwards), cut to ``--from/--to`` and scaled by
  ``--speed``; :meth:`PlayTake.source` is the glove the loop plays it from and
  :func:`play_parts` the pipeline it goes through (a glove take: the live one; a
  performance: :class:`~handrig.pose.take_pipeline.TakePipeline`, the take as the pose
  source with the live rig's limits, slew limit and relaxed pose).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from firmware_protocol.opengloves import CHANNEL_KEYS
from handrig.app.parts import RigParts
from handrig.clock import Clock
from handrig.config.loading import load_joint_limits
from handrig.devices.glove import GloveSample, GloveSource, ReplayGlove
from handrig.devices.glove_calibration import GloveConfig
from handrig.devices.glove_recording import (
    MAGIC,
    GloveRecording,
    check_channels,
    read_glove_recording,
)
from handrig.errors import ConfigError, DataError
from handrig.outputs.glove_take import GloveTake
from handrig.outputs.recorder import check_new_take, load_performance
from handrig.pose.pipeline import POSE_NAMES, POSE_SIZE
from handrig.pose.take_pipeline import PoseExpander, TakePipeline, copy_pose

TakeKind = Literal["glove", "performance"]


def glove_channel_names(cfg: GloveConfig) -> tuple[str, ...]:
    """A name for each raw channel the glove file reads (its curve), for a take's header."""
    if cfg.glove.format == "opengloves":
        return CHANNEL_KEYS
    names = [""] * needed_channels(cfg)
    for ch in cfg.channels:
        names[ch.raw_index()] = names[ch.raw_index()] or ch.curve
    return tuple(n or f"ch{i}" for i, n in enumerate(names))


def needed_channels(cfg: GloveConfig) -> int:
    """Raw channels a sample must have for the glove file's calibration."""
    return max(ch.raw_index() for ch in cfg.channels) + 1


def check_glove_take(rec: GloveRecording, path: str | Path, cfg: GloveConfig,
                     glove_file: Path | None = None) -> None:
    """:func:`~handrig.devices.glove_recording.check_channels` against the glove file."""
    check_channels(rec, needed_channels(cfg), path, glove_file)


def check_glove_take_path(path: str, flag: str = "--record-glove", *,
                          record: str | None = None) -> None:
    """``--record-glove`` (``flag``) checked before the bus opens: a .csv name, not the
    performance take's (``record``), never an existing take (ConfigError naming the flag)."""
    if record and Path(record).resolve() == Path(path).resolve():
        raise ConfigError("the same file as --record", key=flag, value=path,
                          allowed="another file name: the glove take and the performance"
                          " are two takes")
    if Path(path).suffix.lower() != ".csv":
        raise ConfigError("a glove take is a CSV file", key=flag, value=path,
                          allowed="a file name ending in .csv")
    try:
        check_new_take(path)
    except DataError as exc:
        raise ConfigError(str(exc), key=flag, value=path,
                          allowed="a file that does not exist yet") from None


def open_glove_take(path: str, glove: GloveSource, cfg: GloveConfig, *, source: str,
                    log: Callable[[str], None] | None = None,
                    from_first_output: bool = False) -> GloveTake:
    """A glove take at ``path`` that gets every frame ``glove`` sends from now on
    (``from_first_output``: from the frame the loop's first cycle used, see
    :class:`GloveTake`)."""
    take = GloveTake(path, channel_names=glove_channel_names(cfg), rate_hz=cfg.glove.rate_hz,
                     meta={"source": source, "format": cfg.glove.format}, log=log,
                     from_first_output=from_first_output)
    glove.add_tap(take.tap)
    return take


def performance_poses(path: Path) -> tuple[np.ndarray, np.ndarray, bool]:
    """A performance take (``--record``, CSV or BVH) as times (s), whole poses
    (``(N, POSE_SIZE)``: the curves, then the wrist where the take has it, else 0; of
    frames sharing a time, the last one) and whether it has the wrist."""
    t, poses, wrist = load_performance(path)
    full = np.zeros((len(t), POSE_SIZE))
    full[:, :poses.shape[1]] = poses
    if wrist is not None:
        full[:, poses.shape[1]:] = wrist
    keep = np.append(np.diff(t) > 0, True)
    return t[keep], full[keep], wrist is not None


def take_kind(path: str | Path) -> TakeKind:
    """A glove take (the glove recording's first line) or a performance (.csv or .bvh);
    DataError naming the file when it cannot be read."""
    p = Path(path)
    try:
        with p.open("rb") as f:
            first = f.readline(200)
    except FileNotFoundError:
        raise DataError(f"{p}: recording not found") from None
    except OSError as exc:
        raise DataError(f"{p}: cannot read the take: {exc.strerror or exc}") from None
    if first.decode("utf-8", errors="replace").strip() == MAGIC:
        return "glove"
    return "performance"


@dataclass(frozen=True)
class PlayTake:
    """A take ready to play: ``recording`` holds its frames at the times they are played
    (cut to the window, scaled by the speed); for a performance each frame's raw values are
    the full pose (:data:`POSE_NAMES` order)."""

    path: Path
    kind: TakeKind
    recording: GloveRecording
    frames_in_take: int
    start_s: float  # where in the take the window starts (its own time)
    span_s: float  # the window's length in the take's own time
    speed: float

    @property
    def duration_s(self) -> float:
        """How long playing the window takes: the last frame's time after the first."""
        return self.recording.duration_s

    def source(self, clock: Clock, *, loop: bool = False) -> ReplayGlove:
        """The glove the loop plays the take from; it starts when the loop first looks."""
        return ReplayGlove(self.recording, clock, loop=loop, start_at_first_look=True)

    def describe(self) -> str:
        what = "glove take" if self.kind == "glove" else "performance"
        window = (f", {self.start_s:g}..{self.start_s + self.span_s:g} s of it"
                  if self.frames_in_take != len(self.recording) else "")
        speed = f", at {self.speed:g}x speed" if self.speed != 1.0 else ""
        return (f"{self.path} ({what}): {len(self.recording)} frames, {self.duration_s:.2f} s"
                f"{window}{speed}")


def load_play_take(path: str | Path, cfg: GloveConfig, *, speed: float = 1.0,
                   from_s: float | None = None, to_s: float | None = None,
                   glove_file: Path | None = None) -> PlayTake:
    """Read and check a take for ``handrig play --bus`` (see the module docstring)."""
    p = Path(path)
    if not (math.isfinite(speed) and 0.05 <= speed <= 20.0):
        raise ConfigError("speed out of range", key="--speed", value=speed,
                          allowed="0.05..20 (1 = as recorded)")
    kind = take_kind(p)
    if kind == "glove":
        rec = read_glove_recording(p)
        check_glove_take(rec, p, cfg, glove_file)
        t, raw, quat, buttons = rec.t_s, rec.raw, rec.quat_xyzw, rec.buttons
        names, rate = rec.channel_names, rec.nominal_rate_hz
    else:
        t, raw, _ = performance_poses(p)
        quat, buttons, names, rate = None, np.zeros(len(t), dtype=np.int64), POSE_NAMES, 0.0
    if len(t) < 2:
        raise DataError(f"{p}: {len(t)} frame: a take needs two frames or more to play")
    t_rel = t - t[0]
    total = float(t_rel[-1])
    start = 0.0 if from_s is None else float(from_s)
    end = total if to_s is None else float(to_s)
    if not 0.0 <= start <= total:
        raise ConfigError(f"{p} lasts {total:.3f} s", key="--from", value=start,
                          allowed=f"0..{total:.3f} seconds into the take")
    if end <= start:
        raise ConfigError(f"the window ends before it starts ({start:g} s)", key="--to",
                          value=end, allowed=f"more than --from, at most {total:.3f} s")
    window = (t_rel >= start - 1e-9) & (t_rel <= end + 1e-9)
    if not window.any():
        raise ConfigError(f"no frame of {p} lies in {start:g}..{end:g} s", key="--from/--to",
                          value=f"{start:g}..{end:g}", allowed=f"a window inside 0..{total:.3f} s")
    sel = np.flatnonzero(window)
    t_play = (t_rel[sel] - t_rel[sel[0]]) / speed
    played = GloveRecording(
        t_play, np.ascontiguousarray(raw[sel]), np.ascontiguousarray(buttons[sel]), names,
        None if quat is None else np.ascontiguousarray(quat[sel]), rate * speed,
        {"take": str(p)})
    return PlayTake(p, kind, played, len(t), float(t_rel[sel[0]]),
                    float(t_rel[sel[-1]] - t_rel[sel[0]]), float(speed))


def play_parts(parts: RigParts, take: PlayTake) -> RigParts:
    """The parts a take plays through: a glove take's are the live rig's; a performance's
    pipeline is a :class:`TakePipeline` with the live pipeline's servos, limits, slew
    limit, sag (for the relaxed pose only) and retarget, the take's pose as the controls
    and the glove file's fixed forearm as the forearm."""
    if take.kind == "glove":
        return parts
    return pose_parts(parts)


def pose_parts(parts: RigParts) -> RigParts:
    """The parts a full pose (:data:`POSE_NAMES` order) drives as the loop's controls:
    a performance played (:func:`play_parts`), or a program's commands
    (:mod:`handrig.app.robot_loop`)."""
    live = parts.pipeline
    rest = live.expander.expand(np.asarray(live.control_means_deg, dtype=np.float64))
    pipeline = TakePipeline(
        PoseExpander(np.asarray(rest, dtype=np.float64)), parts.sag, live.servo_joints,
        servo_limits_deg=np.stack([live.servo_low, live.servo_high], axis=1),
        limits=load_joint_limits(), slew_deg_s=live.slew_deg_s, sag_gain=live.sag_gain,
        left_hand=live.left_hand, left_forearm_deg=live.left_forearm_deg,
        control_means_deg=PoseExpander(rest).control_means_deg, retarget=live.retarget)
    forearm = (parts.glove_config.forearm.inclination_deg,
               parts.glove_config.forearm.rotation_deg)
    return dataclasses.replace(parts, pipeline=pipeline, controls=copy_pose,
                               orientation=_FixedForearm(forearm))


class _FixedForearm:
    """The forearm angles of a performance played back: fixed (the take holds its sag)."""

    def __init__(self, angles: tuple[float, float]) -> None:
        self.angles = angles

    def __call__(self, sample: GloveSample) -> tuple[float, float]:
        return self.angles
