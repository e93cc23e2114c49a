"""Torque: on only inside a context, off on every way out, signals included.

Torque-on gives every servo its present position (clamped into its limits) as
goal first; a servo resting slightly outside its limits is brought in slowly
(Profile Velocity), one far outside is refused (likely a wrong zero). Torque-off
is a broadcast Sync Write, then a checked write per servo.
"""

from __future__ import annotations

import contextlib
import logging
import math
import signal
import threading
from collections.abc import Callable
from types import FrameType, TracebackType
from typing import Generic, TypeVar

import numpy as np

from handrig.clock import Clock
from handrig.devices.servo.bus import ServoState
from handrig.devices.servo.faults import FaultHandler
from handrig.devices.servo.goals import GoalWriter
from handrig.devices.servo.link import COMMAND_TIMEOUT_S, Link
from handrig.devices.servo.positions import TICKS_PER_DEG
from handrig.devices.servo.registers import VELOCITY_DPS_PER_UNIT, Reg
from handrig.devices.servo.roster import Roster
from handrig.errors import DeviceError, DeviceTimeoutError, SafetyStop, TorqueOffError

log = logging.getLogger("handrig.devices.servo")

TORQUE_ON_SLACK_DEG = 1.0  # torque-on tolerates this much outside the limits (then clamps)
MAX_APPROACH_DEG = 20.0  # further out than this at torque-on: refuse (likely a wrong zero)
APPROACH_DPS = 30.0  # joint speed that brings a servo resting outside its limits back in
CONFIRM_ATTEMPTS = 3  # torque-off: attempts per servo to confirm it
CONFIRM_BUDGET_S = 1.0  # torque-off: time for all the confirmations
CONFIRM_PASSES = 3  # torque-off: rounds over the servos that have not answered yet (once
#                     another has: a stall of the bus or the host passes, a dead bus does not)
# Caught inside a torque context: the loop's graceful stop (on_signal), else an exception.
STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP, signal.SIGQUIT)


class TorqueControl:
    """Torque on and off for the servos of ``roster``.

    ``read_every_servo(purpose)`` reads until every servo has answered; ``read`` is
    one state read; ``write_goals`` the bus's goal write (clamped, counted).
    """

    def __init__(
        self, roster: Roster, link: Link, writer: GoalWriter, faults: FaultHandler,
        clock: Clock, notes: list[str], read_every_servo: Callable[[str], ServoState],
        read: Callable[[], ServoState], write_goals: Callable[[np.ndarray], int],
    ) -> None:
        self.roster = roster
        self.link = link
        self.writer = writer
        self.faults = faults
        self.clock = clock
        self.notes = notes
        self.read_every_servo = read_every_servo
        self.read = read
        self.write_goals = write_goals
        self.hold_outside_limits = False
        # Profile Velocity units (0.229 rpm of the servo) for APPROACH_DPS of the joint
        self._approach_units = [
            max(1, round(APPROACH_DPS * abs(t) / TICKS_PER_DEG / VELOCITY_DPS_PER_UNIT))
            for t in roster.ticks_per_deg]

    @property
    def enabled(self) -> bool:
        return self.faults.torque_on

    def enable(self) -> None:
        """Goals where the servos are, torque on, watchdog armed (DeviceError if refused)."""
        r = self.roster
        # Profile Velocity is RAM: clear what an earlier run that died mid-approach left
        self.link.sync_write(Reg.PROFILE_VELOCITY, [0] * r.n)
        pos = self.read_every_servo("enable torque").positions_deg
        excess = np.maximum(r.min_deg - pos, pos - r.max_deg)
        outside = excess > TORQUE_ON_SLACK_DEG
        slow: list[int] = []  # servos given an approach speed, to be reset
        try:
            if outside.any() and self.hold_outside_limits:  # calibration: hold them
                for i in np.flatnonzero(~r.absent).tolist():
                    self.link.write_register(i, Reg.GOAL_POSITION, r.ticks(i, float(pos[i])))
                self.writer.remember(pos)  # a reboot re-sends where they were held
            else:
                self._refuse_far(pos, excess)
                # a joint slightly out (a limp puppet on its stop) is brought in slowly
                for j in np.flatnonzero(outside).tolist():
                    slow.append(j)
                    self.link.write_register(j, Reg.PROFILE_VELOCITY, self._approach_units[j])
                self.write_goals(pos)  # hold where they are, clamped into the limits
            self.faults.note_torque(True)
            for i in range(r.n):
                if not r.absent[i]:  # a servo left out at start-up gets no torque
                    self.link.write_register(i, Reg.TORQUE_ENABLE, 1)
            self.faults.arm_watchdog()
            self.link.transport.judge_answers(True)
            if slow:
                self._finish_approach(np.array(slow), float(excess.max()))
        finally:
            for j in slow:  # best effort: never leave a servo speed-limited
                with contextlib.suppress(DeviceError):
                    self.link.write_register(j, Reg.PROFILE_VELOCITY, 0)

    def _refuse_far(self, pos: np.ndarray, excess: np.ndarray) -> None:
        r = self.roster
        far = excess > MAX_APPROACH_DEG
        if not far.any():
            return
        bad = [f"{r.describe(int(i))} is at {pos[i]:.1f} deg, outside its limits "
               f"[{r.min_deg[i]:g}, {r.max_deg[i]:g}]" for i in np.flatnonzero(far)]
        raise DeviceError(
            f"cannot enable torque {r.where()}: {'; '.join(bad)}. That is more than "
            f"{MAX_APPROACH_DEG:g} deg out (a wrong zero?): move the joint into range by "
            "hand, or re-zero it with `handrig calibrate servos`")

    def _finish_approach(self, indices: np.ndarray, excess_deg: float) -> None:
        """Wait (bounded) for servos brought in slowly to reach their limits; a servo that
        does not get there in time (blocked, or not answering) is a DeviceError, so torque
        goes off rather than the servo finishing the move at full speed."""
        r = self.roster
        lo = r.min_deg[indices] - TORQUE_ON_SLACK_DEG
        hi = r.max_deg[indices] + TORQUE_ON_SLACK_DEG
        end = self.clock.now() + excess_deg / APPROACH_DPS * 2.0 + 0.5
        while True:
            self.write_goals(self.writer.last_goal_deg)  # keeps the watchdog fed
            state = self.read()
            pos = state.positions_deg[indices]
            inside = ~state.stale[indices] & (pos >= lo) & (pos <= hi)
            if inside.all():
                break
            if self.clock.now() >= end:
                late = [r.describe(int(i)) for i in indices[~inside]]
                raise DeviceError(
                    f"torque-on {r.where()}: {', '.join(late)} did not come into its "
                    f"limits at {APPROACH_DPS:g} deg/s: blocked or not answering? "
                    "Torque is off again; free the joint and retry")
            self.clock.sleep(0.01)
        for i in indices:
            self.notes.append(f"{r.describe(int(i))} rested outside its limits at torque-on: "
                              f"brought in at {APPROACH_DPS:g} deg/s")

    def disable(self) -> list[str]:
        """Torque off on every servo and watchdog cleared; returns the servos that failed.

        The broadcast reaches every servo that hears the bus; each is then asked to
        confirm, ``CONFIRM_ATTEMPTS`` times at most and within ``CONFIRM_BUDGET_S`` in
        all (a bus that stopped answering must not hold the exit for 8 attempts of
        every servo): the servos left are listed as not confirmed. A servo that did
        not answer is asked again after the others, up to ``CONFIRM_PASSES`` rounds in
        all, once some servo has answered (a stall of the bus, or of an emulator on a
        busy host, passes; a bus where nobody answers gets no second round); one that
        answered with an error is not asked again. After the port
        stopped draining (``transport.wedged``) only the broadcast is tried: nothing
        could be read back, and every servo given torque is named as not confirmed."""
        r = self.roster
        given = [i for i in range(r.n) if not r.absent[i]]  # left out: never given torque
        every = ", ".join(r.describe(i) for i in given)
        t = self.link.transport
        if not t.is_open:
            was_on = self.faults.torque_on
            self.faults.note_torque(False)
            return [f"{every}: not confirmed: port {r.port} is closed"] if was_on else []
        wedged = t.wedged
        t.judge_answers(False)
        try:
            self.link.sync_write(Reg.TORQUE_ENABLE, [0] * r.n)
        except DeviceError as exc:
            self.faults.note_torque(False)
            return [f"{every}: not confirmed: {exc}"]
        if wedged:  # nothing can be read back through a port that stopped draining
            self.faults.note_torque(False)
            return [f"{every}: not confirmed: servo port {r.port} stopped draining (the "
                    "torque-off broadcast is queued behind the bytes it holds)"]
        failed = self._confirm_off(given)
        self.faults.note_torque(False)
        return failed

    def _confirm_off(self, given: list[int]) -> list[str]:
        """Ask each servo of ``given`` to confirm torque off and its watchdog cleared (see
        :meth:`disable`); returns what failed, a servo at most once."""
        r, t = self.roster, self.link.transport
        failed: list[str] = []
        end = self.clock.now() + CONFIRM_BUDGET_S
        to_write = {i: [Reg.TORQUE_ENABLE, Reg.BUS_WATCHDOG] for i in given}  # unconfirmed
        silent: dict[int, str] = {}  # a servo's last timeout, while it is asked again
        rounds = dict.fromkeys(given, 0)
        pending, alive = list(given), False
        for _ in range(CONFIRM_PASSES):
            unanswered: list[int] = []  # asked again after the others, while time remains
            for k, i in enumerate(pending):
                rounds[i] += 1
                try:
                    while to_write[i]:
                        left = end - self.clock.now()
                        if left <= 0:
                            return failed + self._out_of_time(pending[k:] + unanswered, silent)
                        # no attempt may outlast the budget by more than one reply's wait
                        attempts = max(1, min(CONFIRM_ATTEMPTS,
                                              math.ceil(left / COMMAND_TIMEOUT_S)))
                        self.link.write_register(i, to_write[i][0], 0, attempts=attempts)
                        to_write[i].pop(0)
                        alive = True
                except DeviceError as exc:
                    if t.wedged or not t.is_open:  # the port failed: nobody else can be asked
                        rest = sorted(pending[k:] + unanswered)
                        names = ", ".join(r.describe(j) for j in rest)
                        return [*failed, f"{names}: not confirmed: {exc}"]
                    if isinstance(exc, DeviceTimeoutError):
                        silent[i] = str(exc)
                        unanswered.append(i)
                        continue
                    alive = True  # answered with an error: asking again won't help
                    failed.append(self._named(i, str(exc)))
            pending = unanswered
            if not pending or not alive:
                break
        return failed + [self._named(i, silent[i]) + (
            f" (asked in {rounds[i]} rounds)" if rounds[i] > 1 else "") for i in pending]

    def _named(self, i: int, text: str) -> str:
        name = self.roster.describe(i)
        return text if text.startswith(name) else f"{name}: {text}"

    def _out_of_time(self, rest: list[int], silent: dict[int, str]) -> list[str]:
        """The budget ran out: a servo that had gone silent says so, the others that
        they were not asked in time."""
        out = [self._named(i, silent[i]) + f" (asked again until the {CONFIRM_BUDGET_S:g} s "
               "for confirmations ran out)" for i in sorted(rest) if i in silent]
        unasked = [self.roster.describe(i) for i in sorted(rest) if i not in silent]
        if unasked:
            out.append(f"{', '.join(unasked)}: not confirmed (the {CONFIRM_BUDGET_S:g} s for "
                       "confirmations went on the servos before)")
        return out


T = TypeVar("T")


class TorqueContext(Generic[T]):
    """Torque on inside, off on every way out (what a bus's ``torque()`` returns).

    ``is_on``, ``enable`` and ``disable`` are the bus's torque state and switches
    (``disable`` returns the servos it failed to switch off); entering returns
    ``device``. Signals are handled as :meth:`DynamixelBus.torque` describes.
    """

    def __init__(
        self, device: T, *, is_on: Callable[[], bool], enable: Callable[[], None],
        disable: Callable[[], list[str]], handle_signals: bool,
        on_signal: Callable[[str], None] | None,
    ) -> None:
        self.device = device
        self._is_on = is_on
        self._enable = enable
        self._disable = disable
        self.handle_signals = handle_signals
        self.on_signal = on_signal
        self.signals_seen = 0
        self._cleaning = False
        self._saved: dict[int, object] = {}
        self.failed: list[str] = []

    def _handler(self, signum: int, frame: FrameType | None) -> None:
        name = signal.Signals(signum).name
        if self._cleaning:
            log.warning("%s during torque-off: finishing the torque-off first", name)
            return
        self.signals_seen += 1
        if self.on_signal is not None and self.signals_seen == 1:
            self.on_signal(name)
            return
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        raise SafetyStop(f"{name} received: stopping the servos with torque off")

    def _install(self) -> None:
        if not self.handle_signals or threading.current_thread() is not threading.main_thread():
            return
        for sig in STOP_SIGNALS:
            self._saved[sig] = signal.signal(sig, self._handler)

    def _restore(self) -> None:
        for sig, old in self._saved.items():
            signal.signal(sig, old)  # type: ignore[arg-type]
        self._saved.clear()

    def __enter__(self) -> T:
        if self._is_on():
            raise DeviceError("torque is already on: torque() contexts do not nest")
        self._install()
        try:
            self._enable()
        except BaseException:
            self._off()
            raise
        return self.device

    def _off(self) -> None:
        self._cleaning = True
        try:
            self.failed = self._disable()
        finally:
            self._restore()
            self._cleaning = False

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._off()
        if self.failed and exc_type is None:
            raise TorqueOffError("torque off failed: " + "; ".join(self.failed))
