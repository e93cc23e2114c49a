"""The glove as a LeRobot teleoperator (``handrig_glove``): handrig's side of it.

The glove runs through the show's pipeline (the calibration ``handrig calibrate glove``
wrote, the map, the sag where the rig has it, the joint limits) in a thread of its own
(:class:`~handrig.app.lerobot.glove_stream.GloveStream`); :meth:`GloveTeleop.action`
never reads the port. Its action is the 50 human curves (``<curve>.pos``, degrees,
:data:`handrig.hand.CURVE_NAMES`), or with ``robot`` (a preset such as ``"leap"`` or a
robot rig file) that robot's joint targets (``<joint>.pos``, degrees, the robot model's
convention) through the preset's retarget table, clipped to its limits: what the
robot's own loop would make of that pose.

``port``: ``"sim"`` (``handrig sim-glove`` streaming a recording, the shipped demo by
default, on a pty), ``replay:FILE`` (a glove take played in this process), a serial
port, or ``opengloves:PORT``. ``fps``: the caller's frame rate; each call then gets the
pose at its frame's time (:class:`~handrig.app.lerobot.glove_stream.FrameGrid`), else
the newest at the call.
"""

from __future__ import annotations

import contextlib
import logging
import math
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from handrig import hand
from handrig.app.factory import open_glove
from handrig.app.lerobot.glove_stream import FloatArray, FrameGrid, GloveStream
from handrig.app.parts import RigParts, build_parts
from handrig.app.port_processes import PortProcess
from handrig.app.robot_api import RobotHand
from handrig.app.simulator import demo_recording
from handrig.app.sources import glove_file
from handrig.clock import Clock, MonotonicClock
from handrig.config.rig import SIM_PORT
from handrig.devices.glove.source import GloveSample
from handrig.errors import ConfigError, HandrigError

log = logging.getLogger(__name__)
FIRST_SAMPLE_S = 10.0
""":meth:`GloveTeleop.connect` waits this long for the glove's first sample."""
SIM_RATE_HZ = 200.0
"""The simulated glove's frame rate (``handrig sim-glove --rate``)."""


class GloveTeleop:
    """The glove, opened by :meth:`connect`, its newest pose by :meth:`action`
    (module docstring). ``glove_config``: a glove file (default: handrig's rule, your
    ``handrig calibrate glove`` file, else the shipped one). ``recording``: what the
    simulated glove streams. ``max_lag_s``: :class:`FrameGrid`'s."""

    def __init__(self, *, port: str = SIM_PORT, robot: str | None = None,
                 glove_config: str | None = None, recording: str | None = None,
                 fps: float | None = None, max_lag_s: float = 0.1,
                 clock: Clock | None = None) -> None:
        if fps is not None and not (0.0 < fps <= 1000.0):
            raise ConfigError("not a frame rate", key="fps", value=fps,
                              allowed="0 < fps <= 1000, the --dataset.fps of the recording")
        if not max_lag_s > 0.0:
            raise ConfigError("not a lag", key="max_lag_s", value=max_lag_s,
                              allowed="seconds > 0")
        self.port = port
        self.robot = robot
        self.recording = recording
        self._glove_config = glove_config
        self._clock = clock or MonotonicClock()
        self._parts: RigParts = build_parts(robot, glove_config)
        self._robot_hand = RobotHand(robot, port=SIM_PORT) if robot else None
        joints = (self._robot_hand.joint_names if self._robot_hand is not None
                  else hand.CURVE_NAMES)
        self.names = tuple(f"{j}.pos" for j in joints)
        self.grid = FrameGrid(fps, max_lag_s) if fps else None
        self._stack: contextlib.ExitStack | None = None
        self._stream: GloveStream | None = None
        self._silent = False
        self._reanchored_seen = 0
        self._early_said = False
        self._behind_seen = (0, 0)  # the stream's (lost, late_answers) last said
        self._behind_said_s = -math.inf  # ... and when

    # ------------------------------------------------------------- calibration

    @property
    def glove_file(self) -> Path:
        """The glove file (calibration) in use."""
        return self._parts.glove_file or Path()

    @property
    def glove_timeout_s(self) -> float:
        """How long the glove may be silent before the action is the relaxed pose (the
        rig's ``[loop] glove_timeout_s``)."""
        return self._parts.rig_config.loop.glove_timeout_s

    @property
    def is_calibrated(self) -> bool:
        """Whether the glove file is a calibration: yours (``handrig calibrate glove``,
        or one given), or the simulated glove's (the shipped file was made for it)."""
        if self.port == SIM_PORT or self.port.startswith("replay:") or self._glove_config:
            return True
        return not glove_file(self._parts.rig_file, self._parts.rig_config,
                              None).why.startswith("shipped")

    def calibrate_argv(self) -> list[str]:
        """``handrig calibrate glove`` on this glove's port, as a command line."""
        argv = [sys.executable, "-m", "handrig.cli", "calibrate", "glove"]
        if self.port not in (SIM_PORT, "") and not self.port.startswith("replay:"):
            argv += ["--glove", self.port]
        return argv

    def calibrate(self) -> None:
        """Run ``handrig calibrate glove`` in this terminal (its prompts, its file): the
        teleoperator's calibration is handrig's, not a second one."""
        if self.port == SIM_PORT or self.port.startswith("replay:"):
            log.info("the simulated glove needs no calibration (the shipped glove file)")
            return
        done = subprocess.run(self.calibrate_argv(), check=False)
        if done.returncode != 0:
            raise HandrigError(f"handrig calibrate glove ended with {done.returncode}")

    # ------------------------------------------------------------ open / close

    @property
    def is_connected(self) -> bool:
        return self._stream is not None

    def connect(self) -> None:
        """Open the glove (``port="sim"``: start the emulated one) and its thread; return
        once its first sample is in."""
        if self._stream is not None:
            raise HandrigError("the glove is already connected")
        stack = contextlib.ExitStack()
        try:
            spec = self.port
            if spec == SIM_PORT:
                recording = self.recording or str(demo_recording())
                spec = stack.enter_context(PortProcess(
                    ["sim-glove", recording, "--rate", f"{SIM_RATE_HZ:g}", "--loop"],
                    "the glove emulator (handrig sim-glove)")).port()
            parts = self._parts
            glove = open_glove(spec, parts.glove_config, self._clock, parts.glove_file)
            stream = stack.enter_context(GloveStream(glove, self.pose_function(),
                                                     self._clock))
            stream.wait_first(FIRST_SAMPLE_S)
        except BaseException:
            stack.close()
            raise
        self._stack, self._stream = stack, stream

    def disconnect(self) -> None:
        """Close the glove (and the emulated one). Idempotent."""
        stack, self._stack, self._stream = self._stack, None, None
        if stack is not None:
            stack.close()

    def pose_function(self) -> Callable[[GloveSample], FloatArray]:
        """One glove sample -> the action's values: controls (calibration, map, the glove
        file's filter, whose state is this teleoperator's: one thread, every sample in
        order), the full pose with sag, clamped to the joint limits, the curves (or the
        robot's joints)."""
        parts = self._parts
        pipeline = parts.pipeline
        controls = np.zeros(len(parts.expander.controls))
        pose = np.zeros(len(pipeline.pose))
        robot = self._robot_hand
        n_curves = len(hand.CURVE_NAMES)

        def pose_of(sample: GloveSample) -> FloatArray:
            parts.controls(sample.raw, sample.host_time_s, controls)
            inclination, rotation = parts.orientation(sample)
            np.clip(pipeline.full_pose(controls, inclination, rotation), pipeline.pose_low,
                    pipeline.pose_high, out=pose)
            if robot is not None:
                return np.asarray(robot.targets_deg(pose[:n_curves]), dtype=np.float64)
            return pose[:n_curves].copy()
        return pose_of

    def relaxed(self) -> FloatArray:
        """The action's values of the relaxed pose (a silent glove's), in :attr:`names` order."""
        pipeline = self._parts.pipeline
        forearm = self._parts.glove_config.forearm
        pose = np.clip(pipeline.relaxed_pose(forearm.inclination_deg, forearm.rotation_deg),
                       pipeline.pose_low, pipeline.pose_high)[:len(hand.CURVE_NAMES)]
        if self._robot_hand is not None:
            return np.asarray(self._robot_hand.targets_deg(pose), dtype=np.float64)
        return np.array(pose)

    # ------------------------------------------------------------------ action

    def _say_off_grid(self, grid: FrameGrid) -> None:
        """Log a call the grid re-anchored: each time the caller fell behind, once for
        a caller that asks faster than the grid (each call then gets the newest pose)."""
        if grid.reanchored > self._reanchored_seen:
            self._reanchored_seen = grid.reanchored
            log.warning("the caller fell more than %.0f ms behind its %g fps frame grid: "
                        "re-anchored (%d times so far); frames around it are not evenly "
                        "timed", grid.max_lag_s * 1e3, 1.0 / grid.period_s, grid.reanchored)
        if grid.early and not self._early_said:
            self._early_said = True
            log.warning("asked more often than the %g fps frame grid: each call gets the "
                        "newest pose; set --teleop.fps to the caller's frame rate (--fps "
                        "of lerobot-teleoperate, --dataset.fps of lerobot-record)",
                        1.0 / grid.period_s)

    def _say_behind(self, stream: GloveStream) -> None:
        """Log when the glove's thread fell behind since the last call (a machine busy
        enough to starve it): samples lost, or a pose answered before the thread had
        looked up to the frame's time; either may give a frame an older pose."""
        now = (stream.lost, stream.late_answers)
        if now == self._behind_seen or self._clock.now() < self._behind_said_s + 1.0:
            return  # at most once a second
        self._behind_seen, self._behind_said_s = now, self._clock.now()
        log.warning("the glove's thread did not keep up (the host is busy): %d glove "
                    "samples lost, %d poses answered before the thread had read up to "
                    "their frame's time, so far; frames around them may carry an older "
                    "pose", *now)

    def action(self) -> dict[str, float]:
        """The pose at this call's frame time (``fps`` given) or now: the newest sample
        at or before it, through the pipeline. A glove silent for longer than the rig's
        ``[loop] glove_timeout_s`` gives the relaxed pose, as a show eases to it (and
        says so in the log)."""
        stream = self._stream
        if stream is None:
            raise HandrigError("the glove is not connected: call connect() first")
        clock = self._clock
        now = clock.now()
        t = self.grid.frame_time(now) if self.grid is not None else now
        if t > now:
            clock.sleep_until(t)
        if self.grid is not None:
            self._say_off_grid(self.grid)
        got = stream.pose_at(t)
        self._say_behind(stream)
        timeout_s = self.glove_timeout_s
        if got is None or t - got[0] > timeout_s:
            if not self._silent:
                log.warning("no glove sample for over %g s: the relaxed pose", timeout_s)
            self._silent = True
            values = self.relaxed()
        else:
            self._silent = False
            values = got[1]
        return {name: float(v) for name, v in zip(self.names, values, strict=True)}
