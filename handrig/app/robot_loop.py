"""The robot API's background loop: the show's realtime loop with a program as its glove.

:class:`RobotHand <handrig.app.robot_api.RobotHand>` runs the very :class:`Rig` a
glove show runs (its rate, slew limit, joint and servo limits, ``[silence]`` and
``[heat]`` policies, the mode machine's easings) in a thread of its own. The
"glove" is :class:`CommandSource`: it hands the loop the pose the program last
commanded, as a new sample each cycle, so the loop follows it as it follows a
glove and the program can do other work meanwhile. The pose is the full pose
(:data:`~handrig.pose.pipeline.POSE_NAMES`), played through the same
:class:`~handrig.pose.take_pipeline.TakePipeline` as a recorded performance
(``handrig play TAKE --bus``): each servo's joint picked out of it (a robot hand:
retargeted), clamped, slew-limited.

Until the first command the servos hold where they are; a program that sends no
command for ``[loop] glove_timeout_s`` after opening finds the hand easing to the
relaxed pose, as a show whose glove is silent; its first command eases it back.
"""

from __future__ import annotations

import contextlib
import dataclasses
import threading
from collections.abc import Callable

import numpy as np

from handrig.app import factory as app
from handrig.app.parts import RigParts
from handrig.app.robot_signals import StopSignalWake, signals_blocked
from handrig.app.takes import pose_parts
from handrig.clock import Clock
from handrig.devices.glove.source import GloveSample, GloveSource, GloveStats
from handrig.devices.servo.bus import ServoBus, ServoState
from handrig.errors import HandrigError
from handrig.loop.rig import Rig
from handrig.loop.telemetry import LoopSnapshot
from handrig.pose.pipeline import POSE_SIZE
from handrig.realtime import pinned_loop, realtime_priority

FloatArray = np.ndarray


class CommandSource(GloveSource):
    """The pose a program commands, as a glove the loop reads: every :meth:`latest`
    is a new sample holding the newest pose, stamped with the clock's now (the
    command stands until replaced); None before the first :meth:`set_pose`.
    :meth:`set_pose` may be called from any thread (the pose is swapped whole)."""

    def __init__(self, clock: Clock) -> None:
        super().__init__()
        self._clock = clock
        self._pose: FloatArray | None = None
        self._count = 0

    @property
    def name(self) -> str:
        return "robot API commands"

    def set_pose(self, pose_deg: FloatArray) -> None:
        """Follow ``pose_deg`` ((POSE_SIZE,), degrees) from the next cycle on."""
        pose = np.array(pose_deg, dtype=np.float64)
        if pose.shape != (POSE_SIZE,):
            raise ValueError(f"a full pose has {POSE_SIZE} values, got {pose.shape}")
        self._pose = pose

    def latest(self) -> GloveSample | None:
        pose = self._pose
        if pose is None:
            return None
        self._count += 1
        sample = GloveSample(raw=pose, quat=None, buttons=0, estop=False,
                             seq=self._count & 0xFFFF, sensor_time_us=0,
                             host_time_s=self._clock.now(), count=self._count)
        self._newest = sample
        self._taken = self._count
        return sample

    def peek(self) -> GloveSample | None:
        return self._newest

    def has_new(self) -> bool:
        return self._pose is not None

    def stats(self) -> GloveStats:
        return GloveStats(frames_ok=self._count)


def robot_loop_parts(parts: RigParts) -> RigParts:
    """The parts of a robot driven by commands: the performance pipeline
    (:func:`~handrig.app.takes.pose_parts`) and a loop at the rig's fixed rate
    (``[loop] rate_hz``): a program's commands have no frame grid to wake on."""
    loop = dataclasses.replace(parts.rig_config.loop, mode="fixed")
    played = pose_parts(parts)
    return dataclasses.replace(played, rig_config=dataclasses.replace(played.rig_config,
                                                                      loop=loop))


class RobotLoop:
    """A :class:`Rig` on an open bus and a :class:`CommandSource`, run in a thread
    inside the bus's torque context. ``start`` turns torque on and starts the loop;
    ``stop`` ends it (``ease``: easing to the relaxed pose first, as a show's stop;
    else at once) and turns torque off on every way out."""

    def __init__(self, parts: RigParts, bus: ServoBus, clock: Clock, *,
                 log: Callable[[str], None]) -> None:
        self.source = CommandSource(clock)
        self.rig: Rig = app.build_rig(parts, self.source, bus, clock, log=log,
                                      ease_in=True)
        self.bus = bus
        self._loop_cfg = parts.rig_config.loop
        self._log = log
        self._thread: threading.Thread | None = None
        self._stack = contextlib.ExitStack()
        self._wake = StopSignalWake(log)
        self.error: BaseException | None = None
        """What ended the loop early (a device error), raised to the program by
        :meth:`check`."""

    def start(self, *, handle_signals: bool) -> None:
        self.rig.prepare()  # the garbage collected before torque (and its watchdog) goes on
        try:
            # SIGTERM, SIGINT, SIGHUP (handle_signals: the caller's main thread) end the
            # program's block with an exception: torque goes off on the way out
            self._stack.enter_context(self.bus.torque(handle_signals=handle_signals))
            if handle_signals:  # a stop signal that left the main thread blocked wakes it
                self._wake.start()  # (handrig.app.robot_signals)
            self._thread = threading.Thread(target=self._run, name="handrig-robot-loop",
                                            daemon=True)
            with signals_blocked():  # the kernel hands them to the program's threads
                self._thread.start()
        except BaseException:
            self.stop(ease=False)
            raise

    def _run(self) -> None:
        loop = self._loop_cfg
        try:
            with (pinned_loop(loop.pin_cpu, self._log),
                  realtime_priority(loop.realtime_priority, self._log,
                                    short_slice_instead=True)):
                self.rig.run()
        except BaseException as exc:  # handed to the program's thread by check()
            self.error = exc

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def check(self) -> None:
        """Raise what ended the loop, if anything did."""
        if self.error is not None:
            raise HandrigError(f"the robot hand's loop stopped: {self.error}") from self.error
        if self._thread is not None and not self._thread.is_alive():
            raise HandrigError("the robot hand's loop stopped: "
                               f"{self.rig.machine.stop_reason or 'it ended'}")

    def snapshot(self) -> LoopSnapshot | None:
        """The telemetry snapshot (published at most 30 times a second)."""
        return self.rig.telemetry.latest()

    def newest_reading(self) -> ServoState | None:
        """The newest read of the servos, whole (each read is a state of its own, swapped
        in by one reference assignment on the loop's thread); None before the first."""
        state: ServoState | None = self.rig.last_state
        return state

    def stop(self, *, ease: bool) -> None:
        """End the loop (``ease``: to the relaxed pose first), then torque off."""
        try:
            if self._thread is not None:
                if ease:
                    self.rig.request_stop("the robot hand was closed")
                else:
                    self.rig.estop("the robot hand was closed after an error")
                self._thread.join(timeout=self._loop_cfg.relax_time_s + 5.0)
                if self._thread.is_alive():  # torque goes off below in any case
                    self.rig.estop("the loop did not end in time")
                    self._thread.join(timeout=2.0)
        finally:
            try:
                self._stack.close()
            finally:
                self._wake.stop()
