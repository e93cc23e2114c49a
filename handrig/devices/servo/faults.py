"""Fault handling: hardware errors and the reboot policy, the Bus Watchdog, stale runs.

A servo raising its Alert bit has its Hardware Error Status read; the
:class:`~handrig.devices.servo.bus.FaultPolicy` then reboots it (bounded) or stops with a
:class:`~handrig.errors.ServoFault`. The Bus Watchdog (``rig.bus.watchdog_ms``,
20 ms units) stops a servo whose host goes silent; a tripped watchdog (-1) makes
the servo refuse goals until it is cleared with 0 and armed again.

A servo without a valid reading goes through the tiers of the rig file's
``[silence]`` (:class:`SilenceWatch`): a warning, then its goal held, then the
configured action (continue with the others, relax, or stop). What is said names
what was seen: which servos, for how long, whether the host itself was late and
whether every servo went quiet at once; hardware advice is given only when the
host kept time and the other servos answer.
"""

from __future__ import annotations

import logging
from collections import deque

import numpy as np

from handrig.clock import Clock
from handrig.config.rig import SilenceConfig
from handrig.devices.servo.bus import BusStats, FaultPolicy
from handrig.devices.servo.codec import INST_PING, INST_REBOOT, build_instruction
from handrig.devices.servo.goals import GoalWriter
from handrig.devices.servo.link import COMMAND_ATTEMPTS, COMMAND_TIMEOUT_S, Link
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
WATCHDOG_GAP_FRACTION = 0.8
# A read that comes this much later than the usual gap between reads counts as the
# host being late (a loop period is a few milliseconds; a starved host loses tens).
HOST_LATE_S = 0.02
GAP_WARM_UP = 16  # gaps between reads learnt before any is judged late
EVENTS_KEPT = 64
# Tiers of a silent servo.
ANSWERING, WARNED, HELD, ACTED = 0, 1, 2, 3


class SilenceWatch:
    """Tiered responses to servos without a valid reading (``config``: ``[silence]``).

    :meth:`note_read` is told when each read starts (the gaps between reads say
    whether the host was late); :meth:`update` after each read looks at how long
    each servo has gone without a valid reading. ``holding``: servos whose goal is
    held at the last one sent; ``releasing``: servos that answer again, moved back
    to their goals at ``release_step_deg`` per write. ``relax_reason``: set while
    the action ``"relax"`` is in force. ``events``: what happened, one line each,
    taken by :meth:`drain_events`.
    """

    def __init__(self, roster: Roster, readings: Readings, stats: BusStats,
                 config: SilenceConfig, release_step_deg: float) -> None:
        self.roster = roster
        self.readings = readings
        self.stats = stats
        self.config = config
        n = roster.n
        self.tier = np.zeros(n, np.int8)
        self.holding = np.zeros(n, bool)
        self.releasing = np.zeros(n, bool)
        self.steering = False  # holding or releasing any servo
        self.active = False  # any servo past warn_s
        self.relax_reason: str | None = None
        self.events: deque[str] = deque(maxlen=EVENTS_KEPT)
        self.release_step_deg = float(release_step_deg)
        self.emulated = "/pts/" in roster.port or roster.port.startswith("/dev/pty")
        self._reads = np.zeros(n, np.int64)  # reads while silent
        self._goals = np.zeros(n, np.float64)
        self._step = np.zeros(n, np.float64)
        self._t_ref = np.nan  # the first read: nobody is silent since before it
        self._last_read_s = np.nan
        self._usual_gap_s = np.nan
        self._gaps_seen = 0
        self.late_s = 0.0  # the host's worst lateness within the last action_s
        self._late_at = -np.inf
        self._late_reads = 0  # reads that came after their deadline, same window

    # ------------------------------------------------------------------ host timing
    def note_read(self, now: float, late: bool = False) -> None:
        """A read starts at ``now`` (``late``: the caller came after its deadline)."""
        if not np.isfinite(self._t_ref):
            self._t_ref = now
        gap = now - self._last_read_s
        self._last_read_s = now
        usual = self._usual_gap_s
        if not np.isfinite(gap):
            return
        if gap > self.config.action_s:
            # nobody was reading (not a loop): silence counts from this read on
            self._t_ref = now
            self._gaps_seen = 0
            return
        self._gaps_seen += 1
        if self._gaps_seen <= GAP_WARM_UP or not np.isfinite(usual):
            # the cadence is learnt first (commissioning reads back to back, then the loop)
            self._usual_gap_s = gap if not np.isfinite(usual) else usual + 0.25 * (gap - usual)
            return
        lateness = gap - usual
        window_s = self.config.action_s
        if now - self._late_at > window_s:
            self.late_s, self._late_reads = 0.0, 0
        if late:
            self._late_reads += 1
            self._late_at = now
        if lateness >= HOST_LATE_S and lateness >= self.late_s:
            self.late_s, self._late_at = lateness, now
        self._usual_gap_s = usual + 0.02 * (min(gap, 2.0 * usual) - usual)

    # ------------------------------------------------------------------ tiers
    def update(self, now: float) -> None:
        """After a read at ``now``: raise tiers, act on them, release servos that answer.
        DeviceTimeoutError when the action is ``"stop"``."""
        cfg = self.config
        last = np.maximum(self.readings.read_time, self._t_ref)
        silent_s = now - last
        silent = silent_s > cfg.warn_s
        self._reads[silent] += 1
        back = np.flatnonzero((self.tier > ANSWERING) & ~silent)
        if back.size:
            self._recover(back, silent_s)
        if not silent.any():
            self.active = False
            return
        self.active = True
        new = np.where(silent_s > cfg.action_s, ACTED,
                       np.where(silent_s > cfg.hold_s, HELD, WARNED)).astype(np.int8)
        new[~silent] = ANSWERING
        rising = np.flatnonzero(new > self.tier)
        if not rising.size:
            return
        old = self.tier[rising].copy()
        self.tier[rising] = new[rising]
        warned = rising[old < WARNED]
        if warned.size:
            what, why = self.describe(warned, float(silent_s[warned].max()))
            self.stats.silences += int(warned.size)
            self._say(f"{what}; {why}")
        newly_held = rising[(old < HELD) & (new[rising] >= HELD)]
        if newly_held.size:
            self.holding[newly_held] = True
            self.releasing[newly_held] = False
            self.steering = True
            self.stats.held += int(newly_held.size)
            self._say(f"holding {self._names(newly_held)} at the last goal sent "
                      "(goals still go out; no reply is needed for them)")
        acting = rising[(old < ACTED) & (new[rising] >= ACTED)]
        if acting.size:
            self._act(acting, float(silent_s[acting].max()))

    def _act(self, indices: np.ndarray, seconds: float) -> None:
        what, why = self.describe(indices, seconds)
        action = self.config.action
        if action == "stop":
            raise DeviceTimeoutError(
                f"{what} {self.roster.where()} ({self.stats.summary()}); {why}; "
                "[silence] action is stop")
        if action == "relax":
            self.relax_reason = f"{what}; {why}"
            self._say(f"{what}: relaxing every servo until it answers ([silence] action)")
        else:
            rest = ("stays held, the others continue" if len(indices) < self.roster.n
                    else "stay held")
            self._say(f"{what}: {self._names(indices)} {rest} ([silence] action)")

    def _recover(self, back: np.ndarray, silent_s: np.ndarray) -> None:
        reads = self._reads[back]
        self.stats.recoveries += int(back.size)
        self.stats.recovery_reads_max = max(self.stats.recovery_reads_max, int(reads.max()))
        held = bool(self.holding[back].any())
        who = f"{self._names(back)} answer{'s' if back.size in (1, self.roster.n) else ''}"
        self._say(f"{who} again after {int(reads.max())} silent reads"
                  + (": releasing to the goals at the slew limit" if held else ""))
        self.releasing[back] |= self.holding[back]
        self.holding[back] = False
        self.tier[back] = ANSWERING
        self._reads[back] = 0
        if not (self.tier >= ACTED).any():
            self.relax_reason = None

    def describe(self, indices: np.ndarray, seconds: float) -> tuple[str, str]:
        """(what was seen, what it points to) for silent servos ``indices``."""
        r = self.roster
        everyone = len(indices) == r.n or bool((self.tier > ANSWERING).all())
        who = "any servo" if everyone else self._names(indices)
        what = f"no valid reply from {who} for {seconds:.2f} s"
        late = self.late_s >= HOST_LATE_S or self._late_reads > 0
        late = late and self._last_read_s - self._late_at <= self.config.action_s
        late_text = (f"the host was late by {self.late_s * 1e3:.0f} ms"
                     + (f" ({self._late_reads} reads came after their deadline)"
                        if self._late_reads else ""))
        if everyone and late:
            why = (f"{late_text} and every servo went quiet at once: the host "
                   + ("and the emulator are" if self.emulated else "is")
                   + " not keeping up, not a hardware fault (give the loop a CPU of its "
                   "own, see [loop] realtime_priority and pin_cpu, or lower rate_hz)")
        elif everyone and self.emulated:
            why = ("every servo went quiet at once on an emulated bus while the host kept "
                   "time: the emulator is not keeping up (a loaded machine), not a "
                   "hardware fault")
        elif everyone:
            why = ("every servo went quiet at once: check the bus's power supply, the USB "
                   "adapter and the baud rate")
        elif late:
            why = f"{late_text}; the other servos answer: check its cable, power and ID"
        else:
            why = "the other servos answer: check its cable, power and ID"
        return what, why

    def _names(self, indices: np.ndarray) -> str:
        if len(indices) == self.roster.n:
            return "every servo"
        return ", ".join(self.roster.describe(int(i)) for i in indices)

    def _say(self, text: str) -> None:
        log.warning("%s", text)
        self.events.append(text)

    def drain_events(self) -> list[str]:
        """What happened since the last call, oldest first."""
        out = list(self.events)
        self.events.clear()
        return out

    # ------------------------------------------------------------------ goals
    def release_all(self) -> None:
        """Nothing held or being released (torque went on or off)."""
        self.holding[:] = False
        self.releasing[:] = False
        self.steering = False

    def steer(self, goals_deg: np.ndarray, last_goal_deg: np.ndarray) -> np.ndarray:
        """``goals_deg`` with held servos at ``last_goal_deg`` and released ones moving
        back at ``release_step_deg`` per write (a new array; the caller's is untouched)."""
        out = self._goals
        np.copyto(out, goals_deg)
        known = np.isfinite(last_goal_deg)
        hold = self.holding & known
        out[hold] = last_goal_deg[hold]
        rel = self.releasing & known & np.isfinite(out)
        if rel.any():
            step = self._step
            np.subtract(out, last_goal_deg, out=step)
            done = rel & (np.abs(step) <= self.release_step_deg)
            np.clip(step, -self.release_step_deg, self.release_step_deg, out=step)
            out[rel] = last_goal_deg[rel] + step[rel]
            self.releasing[done] = False
        self.releasing &= known
        self.steering = bool(self.holding.any() or self.releasing.any())
        return out


class FaultHandler:
    """What the bus does about hardware errors, watchdogs and servos that stay stale.

    ``torque_on``: set by the torque control; a reboot then gives the servo its
    last goal and torque back, and the watchdogs are kept armed.
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
        rig = roster.rig
        self.silence = SilenceWatch(
            roster, readings, stats, policy.silence or rig.silence,
            rig.loop.slew_deg_s / rig.loop.rate_hz)
        self._torque_on = False

    @property
    def torque_on(self) -> bool:
        return self._torque_on

    @torque_on.setter
    def torque_on(self, on: bool) -> None:
        # torque on or off: goals start from present positions, nothing held over
        self.silence.release_all()
        self._torque_on = bool(on)

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
            log.warning("%s raised Alert but its Hardware Error Status is unreadable: %s",
                        self.roster.describe(index), exc)
            return
        if bits:
            self.hardware_error(index, bits)

    def hardware_error(self, index: int, bits: int) -> None:
        """Servo ``index`` reports Hardware Error Status ``bits``: per policy, reboot or stop."""
        r = self.roster
        self.readings.hw_err[index] = bits
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
        log.warning("%s; rebooting it", what)
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
            log.warning("%s still reports hardware error 0x%02x after a reboot: %s",
                        r.describe(index), remaining, describe_hardware_error(remaining))
        self.link.write_register(index, Reg.RETURN_DELAY_TIME, 0)
        self.link.write_register(index, Reg.STATUS_RETURN_LEVEL, STATUS_RETURN_ALL)
        if self.torque_on:
            goal = self.writer.last_goal_deg[index]
            if not np.isfinite(goal):
                goal = r.hold_deg[index]
            self.link.write_register(index, Reg.GOAL_POSITION, r.ticks(index, float(goal)))
            self.link.write_register(index, Reg.TORQUE_ENABLE, 1)
            self.arm_watchdog()

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
    def arm_watchdog(self) -> None:
        """Bus Watchdog to ``rig.bus.watchdog_ms`` on every servo at once, then checked.

        Broadcast Sync Writes reach every servo in one packet (servo by servo, the
        first ones armed could trip while a lossy bus delays the last); 0 first
        clears a tripped watchdog (-1). Servos not confirmed get checked writes.
        """
        n = self.roster.n
        units = self.watchdog_ms // BUS_WATCHDOG_UNIT_MS
        self.link.sync_write(Reg.BUS_WATCHDOG, [0] * n)
        if units:
            self.link.sync_write(Reg.BUS_WATCHDOG, [units] * n)
        for _ in range(COMMAND_ATTEMPTS):
            values = self.sweep.read(Reg.BUS_WATCHDOG, self.clock.now() + COMMAND_TIMEOUT_S)
            if all(v is not None for v in values):
                break
        for i, value in enumerate(values):
            if value == units:
                continue
            if value is not None:  # answered with another value: set it explicitly
                self.link.write_register(i, Reg.BUS_WATCHDOG, 0)
                if units:
                    self.link.write_register(i, Reg.BUS_WATCHDOG, units)
            else:
                self.link.write_register(i, Reg.BUS_WATCHDOG, units)

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
        log.warning("the bus was silent for %.0f ms (Bus Watchdog %d ms): re-arming the "
                    "watchdogs before the next goals", silent_s * 1e3, self.watchdog_ms)
        n = self.roster.n
        self.link.sync_write(Reg.BUS_WATCHDOG, [0] * n)
        self.link.sync_write(Reg.BUS_WATCHDOG, [self.watchdog_ms // BUS_WATCHDOG_UNIT_MS] * n)

    def check_watchdogs(self, deadline_s: float) -> None:
        """Read every Bus Watchdog back and re-arm them if one tripped."""
        watchdogs = self.sweep.read(Reg.BUS_WATCHDOG, deadline_s)
        tripped = [i for i, v in enumerate(watchdogs) if v == BUS_WATCHDOG_TRIPPED]
        if not tripped:
            return
        self.stats.watchdog_trips += len(tripped)
        log.warning("Bus Watchdog tripped on %s (the bus was quiet for more than %d ms): "
                    "re-arming", ", ".join(self.roster.describe(i) for i in tripped),
                    self.watchdog_ms)
        self.arm_watchdog()

    # ------------------------------------------------------------------ stale runs
    def read_skipped(self, wire_s: float, allowed_s: float) -> None:
        """A read was not sent: the wire could not carry it by its deadline. When the
        caller came after the deadline (the host was late) it is counted in
        ``late_reads`` and left to the silence tiers; otherwise too many in a row raise
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
