"""Drive a robot-hand preset from Python with human hand angles from any source.

A VR tracker, a vision model or a recording gives the 50 human curves
(:data:`handrig.hand.CURVE_NAMES`, degrees, the vocabulary's convention: flexion
positive, abduction positive toward the thumb); :class:`RobotHand` turns them into
the robot's joints through the rig's retarget table and drives its servos::

    from handrig.app.robot_api import RobotHand

    with RobotHand("leap", port="sim") as robot:      # or port="/dev/ttyUSB0"
        robot.move_to({"riIndexMCPy": 45.0, "riIndexPIPy": 60.0}, seconds=1.0)
        print(robot.present_deg())

Inside the ``with`` block the show's realtime loop runs in a thread of its own
(:mod:`handrig.app.robot_loop`): the rig's rate (``[loop] rate_hz``), slew limit
(``slew_deg_s``), the retarget table's ranges and the servos' limits, the
``[silence]`` and ``[heat]`` policies, the easings. :meth:`RobotHand.command` sets
the pose the loop follows and returns at once (stream targets while your program
does other work); :meth:`RobotHand.move_to` goes to a pose over a given time and
returns when the hand is there. Input that is not a pose (a wrong shape, text,
None, a value that is not a finite angle) is refused with a ConfigError naming
it, and the loop keeps following the last good pose. Torque is on only inside
the block and goes off when it ends (an exception or a signal included).
``port="sim"`` runs the same driver against ``handrig sim-bus``, the emulated
servos and the robot's MuJoCo model.
"""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

import numpy as np

from handrig import hand
from handrig.app.factory import read_fields_for, servo_bus
from handrig.app.parts import build_parts
from handrig.app.robot_loop import RobotLoop, robot_loop_parts
from handrig.app.session_exit import torque_is_off
from handrig.clock import Clock, MonotonicClock
from handrig.config.rig_files import rig_file_path
from handrig.devices.servo.bus import ServoBus
from handrig.errors import ConfigError, DeviceTimeoutError, HandrigError
from handrig.pose.pipeline import POSE_SIZE
from handrig.pose.retarget_inverse import check_invertible, human_for_robot
from handrig.pose.robot_rig import RobotRigConfig, robot_retarget

MAX_CURVE_DEG = 360.0
"""A human curve beyond this many degrees either way is no joint angle: refused."""
REACHED_DEG = 1.0
""":meth:`RobotHand.move_to`: a joint read this close to its target is there."""
SETTLE_S = 0.3
""":meth:`RobotHand.move_to`: a joint whose fresh readings moved less than
:data:`SETTLE_DEG` over this long has stopped short (held by a contact)."""
SETTLE_DEG = 0.3
Curves = Mapping[str, float] | Sequence[float] | np.ndarray


@dataclass(frozen=True)
class Reading:
    """One read of the servos by the loop, as :meth:`RobotHand.reading` gives the newest.

    ``t_s``: when the read ended, on the loop's clock (``RobotHand(clock=...)``, by
    default :class:`~handrig.clock.MonotonicClock`: ``time.perf_counter``). By robot
    joint: ``positions_deg`` and ``currents_ma`` (NaN where the loop reads positions
    only) as that read left them, NaN where the servo's last valid reading was older
    than ``[silence] hold_s`` at ``t_s``; ``ages_s``: how long before ``t_s`` each
    value was read (0 for a servo that answered this read; the others of a read of a
    part, ``[bus] read_parts``, answered an earlier one)."""

    t_s: float
    positions_deg: dict[str, float]
    currents_ma: dict[str, float]
    ages_s: dict[str, float]


class RobotHand:
    """A robot-hand preset rig, opened as a context manager.

    ``rig``: a preset name (``"leap"``, ``"orca"``) or a robot rig file. ``port``:
    ``"sim"`` for the emulated bus, a serial device, or None for the rig file's
    ``[bus] port`` (the shipped presets name none: a ConfigError says to pass one).
    ``clock``: the loop's clock (default: the monotonic clock). ``log``: where
    progress lines go (default: nowhere).
    """

    def __init__(self, rig: str | Path = "leap", port: str | None = None, *,
                 clock: Clock | None = None,
                 log: Callable[[str], None] = lambda _line: None) -> None:
        self._parts = build_parts(rig)
        config = self._parts.rig_config
        if not isinstance(config, RobotRigConfig) or config.robot is None:
            raise ConfigError("not a robot rig: it has no [robot] table",
                              file=str(rig_file_path(rig)),
                              allowed="a robot hand preset ('leap', 'orca') or rig file")
        if not (port or config.bus.port):
            raise ConfigError("no servo port: the rig file names no [bus] port",
                              file=str(self._parts.rig_file), key="port", allowed=(
                                  'RobotHand(..., port="/dev/ttyUSB0") for the adapter, '
                                  'port="sim" for the simulated hand'))
        self.rig = config
        self._retarget = robot_retarget(config)
        servo_joints = [s.joint for s in config.servos]
        self._rows = np.array([self._retarget.index(j) for j in servo_joints], dtype=np.intp)
        self._low = np.maximum(np.asarray(self._retarget.low_deg)[self._rows],
                               [s.min_deg for s in config.servos])
        self._high = np.minimum(np.asarray(self._retarget.high_deg)[self._rows],
                                [s.max_deg for s in config.servos])
        # the curves' limits the loop clamps to before it retargets (command_joints)
        self._human_low = np.asarray(self._parts.pipeline.pose_low[:len(hand.CURVE_NAMES)])
        self._human_high = np.asarray(self._parts.pipeline.pose_high[:len(hand.CURVE_NAMES)])
        self._invertible = False  # the retarget table checked for command_joints
        self._port = port
        self._clock = clock or MonotonicClock()
        self._log = log
        self._stack: contextlib.ExitStack | None = None
        self._loop: RobotLoop | None = None
        self._commanded: np.ndarray | None = None  # the last human curves commanded
        self.torque_off_confirmed: bool | None = None
        """After the block: True when every servo read Torque Enable 0 back, None when
        they could not be read."""

    # --------------------------------------------------------------- opening

    def __enter__(self) -> RobotHand:
        stack = contextlib.ExitStack()
        try:
            parts = robot_loop_parts(self._parts)
            opened = stack.enter_context(
                servo_bus(self._port, parts, self._clock, log=self._log))
            bus = opened.bus
            bus.connect()
            # runs once torque is off, before the bus closes: read Torque Enable back
            stack.callback(self._confirm_torque_off, bus)
            loop = RobotLoop(parts, bus, self._clock, log=self._log)
            # SIGTERM, SIGINT, SIGHUP end the block with an exception: torque goes off
            loop.start(handle_signals=threading.current_thread() is threading.main_thread())
        except BaseException:
            stack.close()
            raise
        self._stack, self._loop, self._commanded = stack, loop, None
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self._close(ease=exc_type is None)

    def close(self) -> None:
        """Ease to the relaxed pose, torque off, bus closed, the emulator (``port="sim"``)
        stopped. Idempotent."""
        self._close(ease=True)

    def _close(self, *, ease: bool) -> None:
        stack, loop = self._stack, self._loop
        self._stack, self._loop = None, None
        try:
            if loop is not None:
                loop.stop(ease=ease and loop.running)
        finally:
            if stack is not None:
                stack.close()

    def _confirm_torque_off(self, bus: ServoBus) -> None:
        self.torque_off_confirmed = torque_is_off(bus)

    # ---------------------------------------------------------------- driving

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The robot joints the servos drive, in bus order."""
        return tuple(s.joint for s in self.rig.servos)

    @property
    def reads_current(self) -> bool:
        """Whether the loop reads the servos' currents too (else positions only: what a
        goal write and a read fit into one cycle on the wire)."""
        parts = robot_loop_parts(self._parts)
        return read_fields_for(parts.rig_config, parts.glove_config.glove.rate_hz) == "motion"

    @property
    def torque_on(self) -> bool:
        """Whether the hand is open, its loop running and its torque on."""
        loop = self._loop
        return loop is not None and loop.running and loop.bus.torque_enabled

    def targets_deg(self, curves: Curves) -> np.ndarray:
        """The robot joint angles (bus order, degrees) these human curves ask for,
        clipped to the table's ranges and the servos' limits (no slew, nothing sent)."""
        return self._targets(self._human(curves))

    def command(self, curves: Curves) -> np.ndarray:
        """Have the loop follow the pose of these human curves from its next cycle on,
        and return at once: a mapping of curve names to degrees (curves not named are
        0, the flat hand) or all 50 in :data:`handrig.hand.CURVE_NAMES` order. The
        loop moves the servos there at most at the rig's slew rate. Returns the robot
        joint targets (bus order, degrees, clipped to the limits). Anything that is not
        a pose is refused with a ConfigError, and the loop keeps the last good one."""
        loop = self._open_loop()
        human = self._human(curves)
        targets = self._targets(human)
        self._send(loop, human)
        return targets

    def command_joints(self, joints_deg: Mapping[str, float]) -> np.ndarray:
        """:meth:`command` in the robot's own joints: a mapping of :attr:`joint_names` to
        degrees (the robot model's convention), turned into the human curves the loop
        retargets back to them (:mod:`handrig.pose.retarget_inverse`), so the same
        limits, slew limit and policies apply. Joints not named keep the last command's
        target (the first command names them all). Returns the robot joint targets
        (bus order, degrees, clipped to the limits). A name that is no joint, or a value
        that is no finite angle, is refused with a ConfigError and nothing is sent."""
        loop = self._open_loop()
        rt = self._retarget
        if not self._invertible:
            check_invertible(rt.gain, rt.joint_names)
            self._invertible = True
        unknown = sorted(str(k) for k in set(joints_deg) - set(self.joint_names))
        if unknown:
            raise ConfigError("not a joint of this robot: nothing was sent", key=unknown[0],
                              allowed=", ".join(self.joint_names))
        if self._commanded is not None:
            robot = rt.offset_deg + rt.gain @ np.clip(self._commanded, self._human_low,
                                                      self._human_high)
        else:
            missing = [j for j in self.joint_names if j not in joints_deg]
            if missing:
                raise ConfigError("the first joint command names every joint: nothing was "
                                  "sent", key=missing[0], allowed=", ".join(self.joint_names))
            robot = np.array(rt.offset_deg, dtype=np.float64)
        for name, value in joints_deg.items():
            try:
                deg = float(value)
            except (TypeError, ValueError):
                raise ConfigError("not a number: nothing was sent", key=str(name),
                                  value=value, allowed="degrees") from None
            if not (math.isfinite(deg) and abs(deg) <= MAX_CURVE_DEG):
                raise ConfigError("not a joint angle: nothing was sent", key=str(name),
                                  value=deg, allowed=f"-{MAX_CURVE_DEG:g}..{MAX_CURVE_DEG:g}")
            robot[rt.index(str(name))] = deg
        human = human_for_robot(robot, rt.gain, rt.offset_deg, self._human_low,
                                self._human_high)
        targets = self._targets(human)
        self._send(loop, human)
        return targets

    def move_to(self, curves: Curves, seconds: float = 1.0, *,
                timeout_s: float | None = None) -> dict[str, float]:
        """Go to the pose of these human curves (as :meth:`command` takes them) along a
        straight line from the last pose commanded, over ``seconds``, and return when
        every servo's goal is there and its reading has settled (at the goal, or held
        by a contact); returns :meth:`present_deg`. The rig's slew limit still applies
        (a short ``seconds`` for a long way takes longer). A DeviceTimeoutError after
        ``timeout_s`` (default: ``seconds`` plus the slew-limited time plus 2 s)
        when the loop does not get there (e.g. relaxing for a silent servo)."""
        if not (isinstance(seconds, (int, float)) and math.isfinite(seconds)
                and 0.0 <= seconds <= 3600.0):
            raise ConfigError("not a duration", key="seconds", value=seconds,
                              allowed="0..3600 seconds")
        loop = self._open_loop()
        human = self._human(curves)
        targets = self._targets(human)
        start = self._commanded if self._commanded is not None else human
        clock, rate_hz = self._clock, self.rig.loop.rate_hz
        t0 = clock.now()
        if seconds > 0.0:
            while (t := clock.now() - t0) < seconds:
                self._send(loop, start + (human - start) * (t / seconds))
                clock.sleep_until(clock.now() + 1.0 / rate_hz)
        self._send(loop, human)
        snap = loop.snapshot()
        now_deg = np.array(snap.goals_deg if snap is not None and snap.goals_deg else
                           targets, dtype=np.float64)
        slew_s = float(np.nanmax(np.abs(targets - now_deg), initial=0.0)) / \
            self.rig.loop.slew_deg_s
        deadline = clock.now() + (timeout_s if timeout_s is not None else slew_s + 2.0)
        self._wait_settled(loop, targets, deadline)
        return self.present_deg()

    def _wait_settled(self, loop: RobotLoop, targets: np.ndarray, deadline: float) -> None:
        """Until every goal is at ``targets`` and every joint is within
        :data:`REACHED_DEG` of it, or has stopped: two fresh readings of it at least
        :data:`SETTLE_S` apart moved less than :data:`SETTLE_DEG` (held by a contact)."""
        clock = self._clock
        n = len(targets)
        since_pos = np.full(n, math.nan)  # a joint's reading where its stillness began
        since_t = np.full(n, math.nan)  # ... and when that reading was taken
        while True:
            loop.check()
            snap = loop.snapshot()
            now = clock.now()
            if (snap is not None and len(snap.goals_deg) == n
                    and np.all(np.abs(np.asarray(snap.goals_deg) - targets) <= 1e-6)):
                pos = np.array([math.nan if v is None else v for v in snap.positions_deg])
                read_t = snap.t_s - np.asarray(snap.reading_ages_s, dtype=np.float64)
                moved = ~(np.abs(pos - since_pos) <= SETTLE_DEG)  # NaN: not begun
                since_pos = np.where(moved, pos, since_pos)
                since_t = np.where(moved, read_t, since_t)
                still = (read_t - since_t >= SETTLE_S) & np.isfinite(pos)
                if np.all((np.abs(pos - targets) <= REACHED_DEG) | still):
                    return
            if now > deadline:
                mode = f"{snap.mode} ({snap.mode_reason})" if snap is not None else "no cycle"
                raise DeviceTimeoutError(
                    "move_to: the hand did not get to the pose in time; the loop is "
                    f"{mode}: see [silence], [heat] and the servos' readings "
                    "(present_deg)")
            clock.sleep_until(now + 0.01)

    def goals_deg(self) -> dict[str, float]:
        """The goals the loop last sent, by robot joint (NaN before the first)."""
        snap = self._open_loop().snapshot()
        goals = snap.goals_deg if snap is not None else ()
        return {name: float(goals[i]) if i < len(goals) else math.nan
                for i, name in enumerate(self.joint_names)}

    def reading(self) -> Reading | None:
        """The loop's newest read of the servos (None before its first): taken as the
        read ended, not the telemetry snapshot (published at most 30 times a second), and
        never an average. The loop reads the servos every ``[bus] read_every`` cycles (a
        part of them each time with ``read_parts``): at the rig's rate that is how old
        the newest read can be (20 ms on the LEAP preset: 4 cycles at 200 Hz)."""
        loop = self._open_loop()
        loop.check()
        state = loop.newest_reading()
        if state is None:
            return None
        ages = np.asarray(state.age_s, dtype=np.float64)
        fresh = ages <= self.rig.silence.hold_s
        pos = np.where(fresh, np.asarray(state.positions_deg, dtype=np.float64), math.nan)
        cur = np.where(fresh, np.asarray(state.currents_ma, dtype=np.float64), math.nan)
        names = self.joint_names
        return Reading(t_s=float(state.timestamp_s),
                       positions_deg=dict(zip(names, pos.tolist(), strict=True)),
                       currents_ma=dict(zip(names, cur.tolist(), strict=True)),
                       ages_s=dict(zip(names, ages.tolist(), strict=True)))

    def present_deg(self) -> dict[str, float]:
        """The robot's joint angles as the loop last read them (:meth:`reading`; NaN: no
        reading yet, or none for longer than ``[silence] hold_s``)."""
        reading = self.reading()
        if reading is None:
            return dict.fromkeys(self.joint_names, math.nan)
        return reading.positions_deg

    def present_current_ma(self) -> dict[str, float]:
        """The servos' currents (mA) as the loop last read them, by robot joint; NaN where
        the loop reads positions only (``[bus]`` and the rate leave no time for more) or
        no reading is fresh (as :meth:`present_deg`)."""
        reading = self.reading()
        if reading is None:
            return dict.fromkeys(self.joint_names, math.nan)
        return reading.currents_ma

    # ---------------------------------------------------------------- helpers

    def _open_loop(self) -> RobotLoop:
        if self._loop is None:
            raise HandrigError("the robot hand is not open: use it in a `with RobotHand(...)` "
                               "block")
        return self._loop

    def _send(self, loop: RobotLoop, human: np.ndarray) -> None:
        loop.check()
        pose = np.zeros(POSE_SIZE)
        pose[:len(human)] = human
        loop.source.set_pose(pose)
        self._commanded = human.copy()

    def _targets(self, human: np.ndarray) -> np.ndarray:
        robot = np.asarray(self._retarget.apply(human), dtype=np.float64)
        out = robot[self._rows]
        if not np.isfinite(out).all():
            k = int(np.flatnonzero(~np.isfinite(out))[0])
            raise ConfigError("the pose gives a robot joint no finite angle: nothing was "
                              "sent", key=self.joint_names[k], value=float(out[k]))
        return np.clip(out, self._low, self._high)

    @staticmethod
    def _human(curves: Curves) -> np.ndarray:
        names = hand.CURVE_NAMES
        allowed = ("a mapping of curve names (handrig.hand.CURVE_NAMES) to degrees, or all "
                   f"{len(names)} in that order")
        if isinstance(curves, Mapping):
            unknown = sorted(str(k) for k in set(curves) - set(names))
            if unknown:
                raise ConfigError("not a human curve", key=unknown[0], allowed=(
                    "names of handrig.hand.CURVE_NAMES, e.g. riIndexMCPy"))
            out = np.zeros(len(names))
            for k, name in enumerate(names):
                if name in curves:
                    value = curves[name]
                    try:
                        out[k] = float(value)
                    except (TypeError, ValueError):
                        raise ConfigError("not a number: nothing was sent", key=name,
                                          value=value, allowed="degrees") from None
        elif isinstance(curves, (str, bytes)) or curves is None:
            raise ConfigError(f"not a pose: {curves!r}: nothing was sent", allowed=allowed)
        else:
            try:
                out = np.asarray(curves, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise ConfigError(f"not a pose ({exc}): nothing was sent",
                                  allowed=allowed) from None
            if out.shape != (len(names),):
                raise ConfigError(f"expected {len(names)} human curves, got an array of "
                                  f"shape {out.shape}: nothing was sent", allowed=allowed)
        bad = np.flatnonzero(~np.isfinite(out))
        if bad.size:
            raise ConfigError("a human curve is not a finite number: nothing was sent",
                              key=names[int(bad[0])], value=float(out[bad[0]]))
        wild = np.flatnonzero(np.abs(out) > MAX_CURVE_DEG)
        if wild.size:
            raise ConfigError("a human curve is no joint angle: nothing was sent",
                              key=names[int(wild[0])], value=float(out[wild[0]]),
                              allowed=f"-{MAX_CURVE_DEG:g}..{MAX_CURVE_DEG:g} degrees")
        return out
