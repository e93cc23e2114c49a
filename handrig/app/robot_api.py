"""Drive a robot-hand preset from Python with human hand angles from any source.

A VR tracker, a vision model or a recording gives the 50 human curves
(:data:`handrig.hand.CURVE_NAMES`, degrees, the vocabulary's convention: flexion
positive, abduction positive toward the thumb); :class:`RobotHand` turns them into
the robot's joints through the rig's retarget table and drives its servos::

    from handrig.app.robot_api import RobotHand

    with RobotHand("leap", port="sim") as robot:      # or port="/dev/ttyUSB0"
        robot.command({"riIndexMCPy": 45.0, "riIndexPIPy": 60.0})
        print(robot.present_deg())

The safety is the rig's: goals clipped to the retarget table's ranges and the
servos' limits, each step limited to the rig's slew rate (``[loop] slew_deg_s``)
starting from where the hand is, a curve that is not a finite number refused
with nothing sent, torque switched on only inside the ``with`` block and off when
it ends (an exception or a signal included), and the driver's own checks
(models, Bus Watchdog, goal clamp). ``port="sim"`` runs the same driver against
``handrig sim-bus``, the emulated servos and the robot's MuJoCo model.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from types import TracebackType

import numpy as np

from handrig import hand
from handrig.app.factory import servo_bus
from handrig.app.parts import build_parts
from handrig.app.session_exit import torque_is_off
from handrig.clock import Clock, MonotonicClock
from handrig.config.rig_files import rig_file_path
from handrig.devices.servo.bus import ServoBus
from handrig.errors import ConfigError, HandrigError
from handrig.pose.robot_rig import RobotRigConfig, robot_retarget

READ_BUDGET_S = 0.1
"""How long a read the caller asked for (:meth:`RobotHand.present_deg`, the reading
at the start) may take with its retries. Not the loop's realtime budget (1.5 times
the reply's wire time): a program waiting for an answer would rather have it a few
milliseconds late, from a loaded machine or a USB adapter's latency timer, than NaN."""

Curves = Mapping[str, float] | Sequence[float] | np.ndarray


class RobotHand:
    """A robot-hand preset rig, opened as a context manager.

    ``rig``: a preset name (``"leap"``, ``"orca"``) or a robot rig file. ``port``:
    ``"sim"`` for the emulated bus, a serial device, or None for the rig's own
    ``[bus] port``. ``clock``: times the slew limit (default: the monotonic clock).
    ``log``: where progress lines go (default: nowhere).
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
        self.rig = config
        self._retarget = robot_retarget(config)
        servo_joints = [s.joint for s in config.servos]
        self._rows = np.array([self._retarget.index(j) for j in servo_joints], dtype=np.intp)
        self._low = np.maximum(np.asarray(self._retarget.low_deg)[self._rows],
                               [s.min_deg for s in config.servos])
        self._high = np.minimum(np.asarray(self._retarget.high_deg)[self._rows],
                                [s.max_deg for s in config.servos])
        self._port = port
        self._clock = clock or MonotonicClock()
        self._log = log
        self._stack: contextlib.ExitStack | None = None
        self._bus: ServoBus | None = None
        self._last_deg: np.ndarray | None = None
        self._last_t = 0.0
        self.torque_off_confirmed: bool | None = None
        """After the block: True when every servo read Torque Enable 0 back, None when
        they could not be read."""

    # --------------------------------------------------------------- opening

    def __enter__(self) -> RobotHand:
        stack = contextlib.ExitStack()
        try:
            opened = stack.enter_context(
                servo_bus(self._port, self._parts, self._clock, log=self._log))
            bus = opened.bus
            bus.connect()
            # runs once torque is off, before the bus closes: read Torque Enable back
            stack.callback(self._confirm_torque_off, bus)
            # SIGTERM, SIGINT, SIGHUP end the block with an exception: torque goes off
            stack.enter_context(bus.torque(handle_signals=True))
            state = bus.read_state(self._clock.now() + READ_BUDGET_S, patient=True)
            if state.stale.any():
                missing = [self.joint_names[i] for i in np.flatnonzero(state.stale)]
                raise HandrigError(f"no reading from the servos of {', '.join(missing)}: "
                                   "the hand is not where it can be ramped from")
        except BaseException:
            stack.close()
            raise
        self._stack, self._bus = stack, bus
        self._last_deg = np.clip(state.positions_deg, self._low, self._high)
        self._last_t = self._clock.now()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        """Torque off, bus closed, the emulator (``port="sim"``) stopped. Idempotent."""
        stack, self._stack, self._bus = self._stack, None, None
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
    def torque_on(self) -> bool:
        """Whether the hand is open and its torque on."""
        return self._bus is not None and self._bus.torque_enabled

    def targets_deg(self, curves: Curves) -> np.ndarray:
        """The robot joint angles (bus order, degrees) these human curves ask for,
        clipped to the table's ranges and the servos' limits (no slew, nothing sent)."""
        human = self._human(curves)
        robot = self._retarget.apply(human)
        return np.clip(robot[self._rows], self._low, self._high)

    def command(self, curves: Curves) -> np.ndarray:
        """Send the robot the pose of these human curves: a mapping of curve names to
        degrees (curves not named are 0, the flat hand) or all 50 in
        :data:`handrig.hand.CURVE_NAMES` order. The step from the last goals is limited
        to the rig's slew rate; returns the goals sent (bus order, degrees)."""
        bus = self._open_bus()
        want = self.targets_deg(curves)
        last = want if self._last_deg is None else self._last_deg
        now = self._clock.now()
        # a pause does not earn a jump: at most one cycle's step at the loop's rate
        dt = min(max(0.0, now - self._last_t), 1.0 / self.rig.loop.rate_hz)
        step = self.rig.loop.slew_deg_s * dt
        goals = np.clip(want, last - step, last + step)
        bus.write_goals_deg(goals)
        self._last_deg, self._last_t = goals, now
        return goals

    def present_deg(self) -> dict[str, float]:
        """The robot's joint angles as the servos report them (NaN: no reading)."""
        state = self._open_bus().read_state(self._clock.now() + READ_BUDGET_S, patient=True)
        return {name: float("nan") if state.stale[i] else float(state.positions_deg[i])
                for i, name in enumerate(self.joint_names)}

    # ---------------------------------------------------------------- helpers

    def _open_bus(self) -> ServoBus:
        if self._bus is None:
            raise HandrigError("the robot hand is not open: use it in a `with RobotHand(...)` "
                               "block")
        return self._bus

    @staticmethod
    def _human(curves: Curves) -> np.ndarray:
        names = hand.CURVE_NAMES
        if isinstance(curves, Mapping):
            unknown = sorted(set(curves) - set(names))
            if unknown:
                raise ConfigError("not a human curve", key=unknown[0], allowed=(
                    "names of handrig.hand.CURVE_NAMES, e.g. riIndexMCPy"))
            out = np.zeros(len(names))
            for k, name in enumerate(names):
                if name in curves:
                    out[k] = float(curves[name])
        else:
            out = np.asarray(curves, dtype=np.float64).reshape(-1)
            if out.shape != (len(names),):
                raise ConfigError(f"expected {len(names)} human curves, got {out.size}",
                                  allowed="an array in handrig.hand.CURVE_NAMES order, or a "
                                  "mapping of curve names to degrees")
        bad = np.flatnonzero(~np.isfinite(out))
        if bad.size:
            raise ConfigError("a human curve is not a finite number: nothing was sent",
                              key=names[int(bad[0])], value=float(out[bad[0]]))
        return out
