"""Fault handling: hardware errors and the reboot policy, the Bus Watchdog, stale runs.

A servo raising its Alert bit has its Hardware Error Status read; the
:class:`~handrig.devices.servo.bus.FaultPolicy` then reboots it (bounded) or stops with a
:class:`~handrig.errors.ServoFault`. The Bus Watchdog (``rig.bus.watchdog_ms``,
20 ms units) stops a servo whose host goes silent; a tripped watchdog (-1) makes
the servo refuse goals until it is cleared with 0 and armed again.

What to do about a servo that stops answering is the loop's decision
(:mod:`handrig.loop.silence`): the bus marks its readings stale, with their age.
"""

from __future__ import annotations

import contextlib
import logging
from collections import deque
from collections.abc import Callable

import numpy as np

from handrig.clock import Clock
from handrig.devices.servo.bus import BusStats, FaultPolicy
from handrig.devices.servo.codec import INST_PING, INST_REBOOT, build_instruction
from handrig.devices.servo.goals import GoalWriter
from handrig.devices.servo.link import COMMAND_ATTEMPTS, COMMAND_TIMEOUT_S, Link
from handrig.devices.servo.models import RETURN_DELAY_UNIT_US
from handrig.devices.servo.readings import Readings
from handrig.devices.servo.registers import (
    BUS_WATCHDOG_TRIPPED,
    BUS_WATCHDOG_UNIT_MS,
    STATUS_RETURN_ALL,
    Reg,
    describe_hardware_error,
    describe_status_error,
)
from handrig.devices.servo.roster import Roster
from handrig.devices.servo.sync_read import RegisterSweep
from handrig.errors import DeviceError, DeviceTimeoutError, ServoFault

log = logging.getLogger("handrig.devices.servo")

# A goal write after a silence this fraction of the Bus Watchdog time re-arms it first
# (the servo's clock and ours differ).
EVENTS_KEPT = 64
REARM_ATTEMPTS = 2  # re-arming a watchdog mid-run: a servo that does not answer is silent
WATCHDOG_GAP_FRACTION = 0.8


class FaultHandler:
    """What the bus does about hardware errors, watchdogs and servos that stay stale.

    ``torque_on``: told by the torque control (:meth:`note_torque`); a reboot then gives
    the servo its last goal and torque back, and the watchdogs are kept armed.
    """

    def __init__(
        self, roster: Roster, link: Link, writer: GoalWriter, sweep: RegisterSweep,
        readings: Readings, policy: FaultPolicy, stats: BusStats, clock: Clock,
    ) -> None:
        self.roster = roster
        self.link = link
        self.writer = writer
        self.sweep = sweep
        self.readings = readings
        self.policy = policy
        self.stats = stats
        self.clock = clock
        self.watchdog_ms = roster.rig.bus.watchdog_ms
        self._watchdog_gap_s = (
            WATCHDOG_GAP_FRACTION * self.watchdog_ms / 1000.0 if self.watchdog_ms else np.inf)
        self.skip_run = 0  # reads in a row not sent for lack of wire time
        self._torque_on = False
        # hardware errors, reboots and watchdog trips, for the run's events; until
        # somebody drains them (the loop) they are logged instead
        self.events: deque[str] = deque(maxlen=EVENTS_KEPT)
        self.drained = False
        # given torque back, where it is, a servo found restarted on its own; returns
        # what was done (the bus wires it to its admission part)
        self.on_restart: Callable[[int], str] | None = None

    @property
    def torque_on(self) -> bool:
        return self._torque_on

    def note_torque(self, on: bool) -> None:
        """The torque control switched torque (a reboot then restores it; the watchdog
        is re-armed only while it is on)."""
        self._torque_on = bool(on)

    def _say(self, text: str) -> None:
        """A fault and what was done about it: into the run's events (said once, by the
        loop that drains them), or to the log when nobody drains them."""
        if self.drained:
            self.events.append(text)
        else:
            log.warning("%s", text)

    def drain_events(self) -> list[str]:
        """What was said since the last call, oldest first (see :meth:`_say`)."""
        self.drained = True
        out = list(self.events)
        self.events.clear()
        return out

    # ------------------------------------------------------------------ hardware errors
    def alerts_raised(self) -> None:
        """Handle every servo whose ERR byte in this read raised the Alert bit."""
        for i in np.flatnonzero(self.readings.status_err & 0x80):
            self.hardware_alert(int(i))

    def hardware_alert(self, index: int) -> None:
        """Servo ``index`` raised Alert: read its Hardware Error Status and act on it."""
        try:
            bits = self.link.read_register(index, Reg.HARDWARE_ERROR_STATUS)
        except DeviceError as exc:
            self._say(f"{self.roster.describe(index)} raised Alert but its Hardware Error "
                      f"Status is unreadable: {exc}")
            return
        if bits:
            self.hardware_error(index, bits)

    def hardware_error(self, index: int, bits: int) -> None:
        """Servo ``index`` reports Hardware Error Status ``bits``: per policy, reboot or stop."""
        r = self.roster
        self.readings.note_hardware_error(index, bits)
        self.stats.hardware_errors[index] += 1
        what = (f"{r.describe(index)} hardware error 0x{bits:02x}: "
                f"{describe_hardware_error(bits)} {r.where()}")
        if self.policy.on_hardware_error == "stop":
            raise ServoFault(f"{what}; policy: stop", servo_id=r.ids[index], bits=bits)
        if self.stats.reboots[index] >= self.policy.max_reboots:
            raise ServoFault(
                f"{what}; still there after {int(self.stats.reboots[index])} reboots: "
                "stopping (check the load, supply voltage and temperature)",
                servo_id=r.ids[index], bits=bits,
            )
        self._say(f"{what}; rebooting it")
        self.reboot(index)

    def reboot(self, index: int) -> None:
        """Reboot servo ``index``, wait for it (ServoFault if it does not come back within
        ``policy.reboot_wait_s``), then restore its settings (and torque, if on)."""
        r = self.roster
        sid = r.ids[index]
        # One attempt only: a lost status must not send a second reboot to a
        # servo that is already restarting (it would not answer that one either).
        status = self.link.transact(build_instruction(sid, INST_REBOOT), sid, attempts=1,
                                    n_params=0)
        if status is not None and status.error & 0x7F:
            raise ServoFault(
                f"{r.describe(index)} refused a reboot: {describe_status_error(status.error)}",
                servo_id=sid, bits=status.error,
            )
        self.stats.reboots[index] += 1
        self._wait_for_restart(index)
        remaining = self.link.read_register(index, Reg.HARDWARE_ERROR_STATUS)
        if remaining:
            self._say(f"{r.describe(index)} still reports hardware error 0x{remaining:02x} "
                      f"after a reboot: {describe_hardware_error(remaining)}")
        # the rig's Return Delay Time, as commissioning set it (not 0 whatever the rig says)
        self.link.write_register(index, Reg.RETURN_DELAY_TIME,
                                 int(r.return_delay_us[index]) // RETURN_DELAY_UNIT_US)
        self.link.write_register(index, Reg.STATUS_RETURN_LEVEL, STATUS_RETURN_ALL)
        if not self.torque_on:
            self._say(f"{r.describe(index)} rebooted: back, torque off")
            return
        # torque back on where it is (clamped into its limits), not at its last goal:
        # the loop eases it back to its goals at the slew limit (it sees the reboot)
        try:
            ticks = self.link.read_register(index, Reg.PRESENT_POSITION)
            goal = float(np.clip((ticks - r.zero_ticks[index]) / r.ticks_per_deg[index],
                                 r.min_deg[index], r.max_deg[index]))
            how = f"torque on where it is ({goal:.1f} deg), easing back to its goals"
        except DeviceError:
            goal = float(self.writer.last_goal_deg[index])
            if not np.isfinite(goal):
                goal = float(r.hold_deg[index])
            how = "torque on at its last goal (its position was unreadable)"
        self.link.write_register(index, Reg.GOAL_POSITION, r.ticks(index, goal))
        self.link.write_register(index, Reg.TORQUE_ENABLE, 1)
        remembered = self.writer.last_goal_deg.copy()
        remembered[index] = goal
        self.writer.remember(remembered)
        self.arm_watchdog(strict=False)
        self._say(f"{r.describe(index)} rebooted: {how}")

    def restarted(self, index: int) -> None:
        """Servo ``index`` restarted on its own: given torque back where it is (the bus's
        ``on_restart``), counted with the reboots so that the loop eases it back from
        there, as after a reboot."""
        r = self.roster
        if self.on_restart is None:
            self._say(f"{r.describe(index)} restarted on its own (its Bus Watchdog reads 0) "
                      f"{r.where()}: torque is off in it")
            return
        try:
            how = self.on_restart(index)
        except DeviceError as exc:
            self._say(f"{r.describe(index)} restarted on its own (its Bus Watchdog reads 0) "
                      f"{r.where()} and could not be given torque back: {exc}")
            return
        self.stats.reboots[index] += 1
        self.arm_watchdog(strict=False)
        self._say(f"{r.describe(index)} restarted on its own (its Bus Watchdog reads 0: a "
                  f"power loss?) {r.where()}: {how}")

    def _wait_for_restart(self, index: int) -> None:
        sid = self.roster.ids[index]
        deadline = self.clock.now() + self.policy.reboot_wait_s
        last = self.writer.last_goal_deg
        while True:
            if self.torque_on and not np.isnan(last).any():
                # keep the other servos' Bus Watchdogs fed while this one restarts
                self.writer.resend(last.copy())
            status = self.link.transact(build_instruction(sid, INST_PING), sid, attempts=1,
                                        n_params=3)
            if status is not None:
                return
            if self.clock.now() >= deadline:
                raise ServoFault(
                    f"{self.roster.describe(index)} did not come back within "
                    f"{self.policy.reboot_wait_s} s of a reboot {self.roster.where()}",
                    servo_id=sid,
                )

    # ------------------------------------------------------------------ watchdog
    def arm_watchdog(self, *, strict: bool = True) -> None:
        """Bus Watchdog to ``rig.bus.watchdog_ms`` on every servo at once, then checked.

        Broadcast Sync Writes reach every servo in one packet (servo by servo, the
        first ones armed could trip while a lossy bus delays the last); 0 first
        clears a tripped watchdog (-1). Servos not confirmed get checked writes;
        not ``strict`` (re-arming mid-run), one that does not answer them is left
        to the loop's silence tiers instead of ending the run (the broadcast
        reached it if it hears the bus).
        """
        n = self.roster.n
        units = self.watchdog_ms // BUS_WATCHDOG_UNIT_MS
        self.link.sync_write(Reg.BUS_WATCHDOG, [0] * n)
        if units:
            self.link.sync_write(Reg.BUS_WATCHDOG, [units] * n)
        for _ in range(COMMAND_ATTEMPTS if strict else 1):
            values = self.sweep.read(Reg.BUS_WATCHDOG, self.clock.now() + COMMAND_TIMEOUT_S)
            if all(v is not None for v in values):
                break
        for i, value in enumerate(values):
            if value == units or self.roster.absent[i]:  # left out at start-up: not asked
                continue
            if value is not None:  # answered with another value: set it explicitly
                self.link.write_register(i, Reg.BUS_WATCHDOG, 0)
                if units:
                    self.link.write_register(i, Reg.BUS_WATCHDOG, units)
            elif strict:
                self.link.write_register(i, Reg.BUS_WATCHDOG, units)
            else:
                with contextlib.suppress(DeviceTimeoutError):
                    self.link.write_register(i, Reg.BUS_WATCHDOG, units,
                                             attempts=REARM_ATTEMPTS)

    def rearm_after_silence(self) -> None:
        """Before goals: if the host was silent near the Bus Watchdog time, the servos'
        watchdogs may have tripped and they refuse goals until it is cleared; clear
        and re-arm it by broadcast first (two Sync Writes, no replies), counted in
        ``stats.watchdog_gaps``. Housekeeping reads the watchdogs back later."""
        if not self.torque_on or not self.watchdog_ms:
            return
        silent_s = self.clock.now() - self.link.budget.last_tx_s
        if silent_s < self._watchdog_gap_s:
            return
        self.stats.watchdog_gaps += 1
        self._say(f"the bus was silent for {silent_s * 1e3:.0f} ms (Bus Watchdog "
                  f"{self.watchdog_ms} ms): re-arming the watchdogs before the next goals")
        n = self.roster.n
        self.link.sync_write(Reg.BUS_WATCHDOG, [0] * n)
        self.link.sync_write(Reg.BUS_WATCHDOG, [self.watchdog_ms // BUS_WATCHDOG_UNIT_MS] * n)

    def check_watchdogs(self, deadline_s: float) -> None:
        """Read every Bus Watchdog back and re-arm them if one tripped."""
        watchdogs = self.sweep.read(Reg.BUS_WATCHDOG, deadline_s)
        tripped = [i for i, v in enumerate(watchdogs) if v == BUS_WATCHDOG_TRIPPED]
        if self.watchdog_ms and self.torque_on:
            # armed by us, read 0: the servo restarted on its own (a power loss): torque
            # off, its RAM settings gone
            restarted = [i for i, v in enumerate(watchdogs)
                         if v == 0 and not self.roster.absent[i]]
            for i in restarted:
                self.restarted(i)
        if not tripped:
            return
        self.stats.watchdog_trips += len(tripped)
        self._say(f"Bus Watchdog tripped on "
                  f"{', '.join(self.roster.describe(i) for i in tripped)} (the bus was quiet "
                  f"for more than {self.watchdog_ms} ms): re-arming")
        self.arm_watchdog(strict=False)

    # ------------------------------------------------------------------ stale runs
    def read_sent(self) -> None:
        """A read went on the wire: the run of reads that did not fit is over."""
        self.skip_run = 0

    def read_skipped(self, wire_s: float, allowed_s: float) -> None:
        """A read was not sent: the wire could not carry it by its deadline. When the
        caller came after the deadline (the host was late) it is counted in
        ``late_reads`` and left to the loop's silence tiers; otherwise too many in a row raise
        (a read that never fits is a configuration to change)."""
        self.stats.skipped_reads += 1
        if allowed_s <= wire_s and allowed_s <= 0.0:
            self.stats.late_reads += 1
            return
        self.skip_run += 1
        if self.skip_run >= self.policy.max_stale_reads:
            raise DeviceTimeoutError(
                f"no read of the servos fitted its deadline {self.skip_run} times in a row "
                f"{self.roster.where()}: one takes {wire_s * 1e3:.2f} ms of wire, the caller "
                f"allowed {allowed_s * 1e3:.2f} ms; raise the baud rate, read fewer fields "
                "or read less often")
