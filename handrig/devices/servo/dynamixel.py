"""``DynamixelBus``: X-series servos on one Protocol 2.0 bus, a facade over its parts.

What this adds to dynamixel-sdk (REFERENCE.md section 1): deadlines on the
injected monotonic clock instead of the SDK's busy-wait; each servo's ERR byte
kept from a Fast Sync Read, whose per-servo running CRCs are checked so a
truncated or partly corrupted reply still yields the servos before the damage;
no crash on a malformed or short reply; a lock instead of the ``is_using`` flag;
stale readings marked; late replies recognised; faults counted, decoded and
handled by a :class:`FaultPolicy`; torque only inside :meth:`DynamixelBus.torque`,
with the Bus Watchdog armed, checked and re-armed.

The parts, one job each: :mod:`~handrig.devices.servo.link` (requests and replies over
the :mod:`~handrig.devices.servo.transport`, with the :mod:`~handrig.devices.servo.wire` budget),
:mod:`~handrig.devices.servo.commissioning`, :mod:`~handrig.devices.servo.goals` (the goal
writer), :mod:`~handrig.devices.servo.reader` (the state reader, over
:mod:`~handrig.devices.servo.fast_read` and :mod:`~handrig.devices.servo.sync_read`),
:mod:`~handrig.devices.servo.faults` and :mod:`~handrig.devices.servo.torque`; packets are
built and parsed by :mod:`~handrig.devices.servo.codec` alone.

Units: see :mod:`handrig.devices.servo.bus`. Goal positions go out as ticks
(``RigConfig`` calibration) and are clamped to each servo's ``[min_deg, max_deg]``
and to 0..4095 ticks whatever the caller asks.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

import numpy as np

from handrig.clock import Clock, MonotonicClock
from handrig.config.rig import RigConfig
from handrig.devices.servo import codec
from handrig.devices.servo.admission import Admission
from handrig.devices.servo.bus import BusStats, FaultPolicy, ServoBus, ServoState
from handrig.devices.servo.commissioning import Commissioner
from handrig.devices.servo.fast_read import FastSyncRead
from handrig.devices.servo.faults import FaultHandler
from handrig.devices.servo.goals import GoalWriter
from handrig.devices.servo.link import COMMAND_ATTEMPTS, COMMAND_TIMEOUT_S, Link
from handrig.devices.servo.reader import StateReader
from handrig.devices.servo.readings import ReadFields, Readings, ReadPlan
from handrig.devices.servo.registers import Reg
from handrig.devices.servo.roster import Roster
from handrig.devices.servo.sync_read import RegisterSweep, SyncRead
from handrig.devices.servo.torque import TorqueContext, TorqueControl
from handrig.devices.servo.transport import SerialTransport, Transport
from handrig.devices.servo.wire import (
    WireBudget,
    cycle_bytes,
    goal_write_bytes,
    read_bytes,
    wire_time_s,
)
from handrig.errors import DeviceError, HandrigError
from handrig.realtime import host_cpu_pressure

__all__ = ["DynamixelBus", "ReadFields", "cycle_bytes", "wire_time_s"]

log = logging.getLogger("handrig.devices.servo")

REPLY_POLL_LEAD_S = 50e-6  # default spin_s


# the parts that count what they do, each in a ledger of its own
_PARTS_COUNTING = ("readings", "faults", "plan", "link", "writer", "sweep", "fast", "sync",
                   "reader", "admission")
_PER_SERVO = ("readings", "faults")


class DynamixelBus(ServoBus):
    """The servos of ``rig`` on the serial port ``port`` (a path such as ``/dev/ttyUSB0``).

    ``baud`` defaults to ``rig.bus.baud``; ``clock`` to :class:`MonotonicClock`;
    ``transport`` to a :class:`~handrig.devices.servo.transport.SerialTransport` on ``port``
    (tests pass a fake). ``read_fields`` picks what each read fetches:
    ``"motion"`` (current, velocity and position, 10 bytes per servo) or
    ``"position"`` (4 bytes: the shortest cycle). ``temperature_every``: every that
    many state reads, when the read's deadline leaves time, one more Fast Sync
    Read fetches the temperatures and, with torque on, another checks the Bus
    Watchdogs and re-arms any that tripped (0: never). ``reply_timeout_s`` bounds
    the wait for one reply (default: twice its wire time plus 2 ms);
    ``emulated``: the servos are an emulator's (whoever opened the port knows).
    ``reply_gap_s`` ends a reply that stops flowing (default 1.5 ms, a USB
    adapter's latency-timer period with margin, plus 32 byte times). ``spin_s``:
    poll for a Fast Sync Read reply, instead of sleeping, from ``spin_s`` before
    the instant the wire would deliver it until shortly after (0: always sleep).
    A sleeping thread takes tens of microseconds to wake, with cold caches; the
    poll costs about ``spin_s`` plus the reply's lateness in CPU per read
    (``handrig bench bus`` measures both ways). Pass 0 from a SCHED_FIFO thread
    that shares its CPU with the kernel's workers: while it polls, the worker
    that would deliver the reply cannot run there.
    """

    def __init__(
        self,
        port: str,
        rig: RigConfig,
        *,
        baud: int | None = None,
        clock: Clock | None = None,
        fault_policy: FaultPolicy | None = None,
        read_fields: ReadFields = "motion",
        temperature_every: int = 100,
        reply_timeout_s: float | None = None,
        spin_s: float = REPLY_POLL_LEAD_S,
        reply_gap_s: float | None = None,
        transport: Transport | None = None,
        emulated: bool = False,
        missing_ok: bool = False,
    ) -> None:
        self.port = port
        self.emulated = bool(emulated)
        self.rig = rig
        self.baud = int(baud if baud is not None else rig.bus.baud)
        self.clock = clock or MonotonicClock()
        self.policy = fault_policy or FaultPolicy()
        self.roster = Roster(rig, port, self.baud)
        # each part counts what it did in a ledger of its own; ``stats`` sums them
        # (per-servo arrays only where a part counts per servo: the readings' stale
        # counts, the fault handler's hardware errors and reboots)
        self._ledgers = {name: BusStats(self.roster.n if name in _PER_SERVO else 0)
                         for name in _PARTS_COUNTING}
        self.commissioning: list[str] = []  # what connect() found and did, one line each
        self.plan = ReadPlan(read_fields, self._ledgers["plan"], self.roster.where(),
                             self.commissioning)
        codec.warm_up()
        self._lock = threading.RLock()
        self._effort_events: list[str] = []  # limit_effort failures, for drain_events
        self._connected = False
        self._build_parts(transport, reply_timeout_s, reply_gap_s, spin_s, temperature_every)
        self.commissioner.missing_ok = bool(missing_ok)

    def _build_parts(
        self, transport: Transport | None, reply_timeout_s: float | None,
        reply_gap_s: float | None, spin_s: float, temperature_every: int,
    ) -> None:
        roster, own, clock, plan = self.roster, self._ledgers, self.clock, self.plan
        if reply_timeout_s is None:
            wire = wire_time_s(read_bytes(roster.n, plan.data_len, True), self.baud)
            reply_timeout_s = 2.0 * wire + 0.002
        if reply_gap_s is None:
            reply_gap_s = 0.0015 + wire_time_s(32, self.baud)
        self.budget = WireBudget(self.baud, float(reply_gap_s), float(reply_timeout_s))
        self.transport = transport or SerialTransport(self.port, self.baud, clock)
        self.readings = Readings(roster.n, own["readings"], self._total_stats)
        # the host's CPU pressure tells a host-held reply from a silent bus; looked at on
        # the real clock and port only (a fake clock's time is not the host's)
        real = transport is None and isinstance(clock, MonotonicClock)
        pressure = host_cpu_pressure() if real else None
        self.link = Link(self.transport, self.budget, roster, clock, own["link"],
                         self.readings.status_err, pressure)
        self.writer = GoalWriter(roster, self.link, own["writer"])
        self.sweep = RegisterSweep(roster, self.link, plan, own["sweep"])
        self.faults = FaultHandler(roster, self.link, self.writer, self.sweep, self.readings,
                                   self.policy, own["faults"], clock)
        self.fast = FastSyncRead(roster, self.link, self.readings, plan, own["fast"],
                                 float(spin_s))
        self.reader = StateReader(
            self.link, self.readings, plan, self.fast, SyncRead(roster, self.link, self.readings,
                                                                plan, own["sync"]),
            self.sweep, self.faults, self.policy, own["reader"], clock, temperature_every)
        self.commissioner = Commissioner(roster, self.link, plan, self.fast, self.faults, clock,
                                         self.commissioning, self._read_every_servo)
        self.admission = Admission(roster, self.link, self.writer, self.commissioner,
                                   self.faults, own["admission"])
        self.faults.on_restart = self.admission.restore
        self.torque_control = TorqueControl(
            roster, self.link, self.writer, self.faults, clock, self.commissioning,
            self._read_every_servo, self.read_state, self.write_goals_deg)

    # ------------------------------------------------------------------ properties
    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.roster.names

    @property
    def ids(self) -> tuple[int, ...]:
        return self.roster.ids

    @property
    def stats(self) -> BusStats:
        """The bus's counters since it was connected: the parts' ledgers summed (a copy)."""
        return self._total_stats()

    def _total_stats(self) -> BusStats:
        return BusStats.total(tuple(self._ledgers.values()))

    @property
    def torque_enabled(self) -> bool:
        return self.faults.torque_on

    @property
    def last_goals_deg(self) -> np.ndarray:
        """The goals last sent, after clamping (NaN before the first write)."""
        return self.writer.last_goal_deg.copy()

    @property
    def last_write_s(self) -> float:
        """When the last write (goals or a request) was handed to the OS, clock time
        (NaN before the first): where the loop's latency figure ends."""
        return self.link.sent_s

    @property
    def models(self) -> dict[int, int]:
        return self.commissioner.models

    @property
    def firmware(self) -> dict[int, int]:
        return self.commissioner.firmware

    @property
    def read_fields(self) -> ReadFields:
        return self.plan.fields

    @property
    def use_fast_sync_read(self) -> bool:
        """Whether present state is read by Fast Sync Read (False: plain Sync Read)."""
        return self.plan.fast

    @use_fast_sync_read.setter
    def use_fast_sync_read(self, fast: bool) -> None:
        self.plan.fast = bool(fast)

    @property
    def hold_outside_limits(self) -> bool:
        """Torque-on with a servo outside [min_deg, max_deg] holds it where it is instead
        of refusing (for ``handrig calibrate servos``, where the zero is being found)."""
        return self.torque_control.hold_outside_limits

    @hold_outside_limits.setter
    def hold_outside_limits(self, hold: bool) -> None:
        self.torque_control.hold_outside_limits = bool(hold)

    @property
    def reply_timeout_s(self) -> float:
        return self.budget.reply_timeout_s

    @property
    def reply_gap_s(self) -> float:
        return self.budget.reply_gap_s

    @property
    def spin_s(self) -> float:
        return self.fast.spin_s

    def describe(self, index: int) -> str:
        """``"servo 7 (riRingPIPy)"`` for the servo at rig index ``index``."""
        return self.roster.describe(index)

    @property
    def left_out(self) -> tuple[int, ...]:
        """Rig indices of the servos that did not answer at connect and are left out
        (``missing_ok``) until admitted (:meth:`admit`): not commissioned, sent a goal
        or given torque before."""
        return tuple(np.flatnonzero(self.roster.absent).tolist())

    def admit(self, index: int) -> tuple[float | None, str]:
        """Bring servo ``index``, left out at connect and answering now, into the run
        (:mod:`~handrig.devices.servo.admission`): (its goal, or None; what was done).
        A DeviceError on the way leaves it out, said in the line."""
        with self._lock:
            try:
                return self.admission.admit(index)
            except DeviceError as exc:
                if self.transport.wedged or not self.transport.is_open:
                    raise  # the port failed: not the servo's affair
                return None, (f"{self.describe(index)} answered but could not be "
                              f"commissioned: {exc}; still left out")

    def read_wire_s(self, n: int) -> float:
        """Wire time of a present-state read of ``n`` servos: the request and every reply."""
        return self.reader.read_wire_s(n)

    def write_wire_s(self) -> float:
        """Wire time of the goal Sync Write to every servo (the wire model's figure)."""
        return wire_time_s(goal_write_bytes(self.roster.n), self.baud)

    def quiet_wait_s(self) -> float:
        """How long a read asked now would wait, beyond the wire, for the line to go
        quiet after a failed reply (0 almost always): a loop fitting reads into gaps
        counts it, or the bus declines the read."""
        return self.link.quiet_wait_s()

    @property
    def port_stalled(self) -> bool:
        """Whether the port stopped draining (a wedged adapter, a stopped emulator): then
        nothing can be read back through it; set when a write raised it."""
        return self.transport.wedged

    @property
    def last_read_whole(self) -> bool:
        """Whether the last read got every servo at once, no Alert raised (the short way)."""
        return self.reader.last_whole

    # ------------------------------------------------------------------ connect, close
    def connect(self) -> None:
        """Open the port and commission every servo (:mod:`handrig.devices.servo.commissioning`).

        Raises DeviceError listing every servo that is missing or wrong.
        """
        with self._lock:
            if self._connected:
                return
            self.transport.open()
            try:
                self.commissioner.run()
                if self.roster.absent.any():
                    self.writer.leave_out(np.flatnonzero(self.roster.absent))
            except BaseException:
                self.transport.close()
                raise
            self._connected = True

    def close(self) -> None:
        """Torque off (if on) and close the port. Safe to call more than once."""
        with self._lock:
            try:
                if self.faults.torque_on:
                    self.disable_torque()
            finally:
                self.transport.close()
                self._connected = False

    def __enter__(self) -> DynamixelBus:
        self.connect()
        return self

    # ------------------------------------------------------------------ registers
    def read_register(self, index: int, reg: Reg) -> int:
        """Read one control-table item of servo ``index`` (rig order)."""
        with self._lock:
            return self.link.read_register(index, reg)

    def write_register(self, index: int, reg: Reg, value: int) -> None:
        """Write one control-table item of servo ``index`` and check the reply."""
        with self._lock:
            self.link.write_register(index, reg, value)

    def limit_effort(self, index: int, fraction: float) -> bool:
        """Goal PWM (100) of servo ``index`` at ``fraction`` of its PWM Limit (36): in the
        position modes Goal PWM caps the motor's PWM (e-manual, Goal PWM), so the servo
        pushes no harder than that and its current falls with it. RAM: a reboot or power
        cycle lifts it. False, with an event, if the servo does not take it."""
        if not 0.0 < fraction <= 1.0:
            raise ValueError(f"effort fraction must be in (0, 1], got {fraction}")
        try:
            with self._lock:
                limit = self.link.read_register(index, Reg.PWM_LIMIT)
                self.link.write_register(index, Reg.GOAL_PWM, max(1, round(limit * fraction)))
        except HandrigError as exc:
            self._effort_events.append(f"{self.describe(index)}: could not cap its effort "
                                       f"at {fraction:.0%} ({exc})")
            return False
        return True

    def reboot(self, index: int) -> None:
        """Reboot servo ``index`` (clears a hardware error), then restore its settings.

        If torque is on, the servo gets its last goal and torque back, and the Bus
        Watchdog is re-armed. Raises ServoFault if it does not come back within
        ``fault_policy.reboot_wait_s``.
        """
        with self._lock:
            self.faults.reboot(index)

    # ------------------------------------------------------------------ goals
    def write_goals_deg(self, goals_deg: np.ndarray) -> int:
        """Send one goal per servo (joint degrees, rig order) in one Sync Write.

        Each goal is clamped to the servo's ``[min_deg, max_deg]``; a non-finite
        goal is replaced by the last goal sent (or the servo's zero clamped into its
        limits). Returns how many goals were changed that way (also counted in
        ``stats.clamps``). No reply is expected.
        """
        with self._lock:
            self.faults.rearm_after_silence()
            clamped = self.writer.build(goals_deg)
            self.writer.send_built()
        return clamped

    def rehearse_write(self, goals_deg: np.ndarray) -> None:
        """:meth:`ServoBus.rehearse_write`: the goal Sync Write built into the writer's
        scratch packet (no lock: it reads the goals last sent and writes only scratch)."""
        self.writer.rehearse(goals_deg)

    def write_and_read(
        self, goals_deg: np.ndarray, deadline_s: float | None = None
    ) -> tuple[int, ServoState]:
        """``write_goals_deg`` then ``read_state``, both requests in one write to the port.

        The same bytes go on the wire in the same order; the host saves a system
        call and the adapter (or emulator) one wake-up. Returns (clamped, state).
        """
        with self._lock:
            self.faults.rearm_after_silence()
            clamped = self.writer.build(goals_deg)
            self.writer.hold_built()
            try:
                state = self.reader.read(deadline_s)
            finally:
                self.writer.send_held()  # not sent by the read: send it on its own
        return clamped, state

    # ------------------------------------------------------------------ present state
    def read_state(self, deadline_s: float | None = None,
                   part: tuple[int, int] | None = None, *, patient: bool = False
                   ) -> ServoState:
        """Read present state (Fast Sync Read, or Sync Read after a fallback).

        ``part=(i, m)`` reads only part ``i`` of ``m`` (the servos at rig indices
        ``i, i + m, ...``): a shorter read that fits a shorter gap; the others keep
        their last reading (``ServoState.asked`` says which were asked).

        ``deadline_s`` is a time on the bus clock by which the read must end
        (default: ``fault_policy.read_budget_s``, at least 1.5 times the reply's
        wire time plus 1 ms, from when the wire is free of the last goal write);
        failed servos are retried up to ``fault_policy.read_retries`` times while
        time remains. Servos without a valid reply are marked stale, never passed
        off as fresh. A read (or retry) whose request and reply could not both be
        on the wire before the deadline is not sent (``ServoState.sent`` False): its
        servos are marked stale (``stats.skipped_reads``; ``stats.late_reads`` when
        the call came after the deadline); ``max_stale_reads`` skipped reads in a
        row that were not late raise DeviceTimeoutError. A servo raising its Alert
        bit is handled per policy (reboot or ServoFault). What to do about a servo
        that stays silent is the loop's decision (:mod:`handrig.loop.silence`).

        ``patient=True`` (a caller that waits for the answer, not the loop: the robot
        API) waits for the replies until ``deadline_s`` instead of each attempt's reply
        deadline (twice the replies' wire time plus 2 ms): a loaded machine or a USB
        adapter's latency timer makes replies late, not missing.
        """
        with self._lock:
            return self.reader.read(deadline_s, part, patient)

    def where(self) -> str:
        return self.roster.where()

    def drain_events(self) -> list[str]:
        """Hardware errors, reboots and Bus Watchdog trips since the last call, one line
        each (once drained, they are no longer logged as well)."""
        with self._lock:
            out = self.faults.drain_events()
            if self._effort_events:
                out += self._effort_events
                self._effort_events = []
            return out

    def housekeeping(self, deadline_s: float) -> bool:
        """Between state reads: the Bus Watchdogs, then the temperatures, when
        ``temperature_every`` reads have passed and the wire can carry them by
        ``deadline_s``. The next :meth:`read_state` returns what was read. True if
        they ran."""
        with self._lock:
            return self.reader.housekeeping(deadline_s)

    def _read_every_servo(self, purpose: str) -> ServoState:
        """Read until every servo has given a valid reading (up to COMMAND_ATTEMPTS reads).

        On an emulated bus, or any pseudo-terminal (a program answers there, not a
        UART), each read waits for its replies until its deadline (``patient``): an
        emulator shares the host's CPUs, and on a busy machine its replies come late,
        not never; the realtime loop's reads stay strict."""
        seen = np.zeros(self.roster.n, bool)
        for _ in range(COMMAND_ATTEMPTS):
            state = self.read_state(self.clock.now() + 4 * COMMAND_TIMEOUT_S,
                                    patient=self.emulated or self.transport.pty)
            seen |= ~state.stale | self.roster.absent  # left out at start-up: not waited for
            if seen.all():
                return state
        bad = [self.describe(int(i)) for i in np.flatnonzero(~seen)]
        raise DeviceError(
            f"cannot {purpose}: no valid present position from {', '.join(bad)} "
            f"{self.roster.where()} in {COMMAND_ATTEMPTS} reads")

    @property
    def connect_notes(self) -> tuple[str, ...]:
        """What :meth:`connect` found and did (commissioning), one line each."""
        return tuple(self.commissioning)

    def confirm_torque_off(self, budget_s: float) -> tuple[bool | None, list[str]]:
        """Torque Enable read back from every servo given torque (the contract's
        :meth:`ServoBus.confirm_torque_off`). A port that stopped draining is not asked
        at all, and the reads stop at ``budget_s`` (the servos not asked are named)."""
        left_out = set(self.left_out)
        given = [i for i in range(self.n_servos) if i not in left_out]
        if self.port_stalled:
            return None, [f"{self.describe(i)}: not read back (servo port {self.port} "
                          "stopped draining)" for i in given]
        unconfirmed: list[str] = []
        on = unread = False
        end = self.clock.now() + budget_s
        for i in range(self.n_servos):
            if self.clock.now() >= end:
                if i not in left_out:
                    unread = True
                    unconfirmed.append(f"{self.describe(i)}: not read back (the "
                                       f"{budget_s:g} s went on the servos before)")
                continue
            try:
                value = self.read_register(i, Reg.TORQUE_ENABLE)
            except HandrigError as exc:
                if i not in left_out:
                    unread = True
                    unconfirmed.append(f"{self.describe(i)}: not read back ({exc})")
                continue
            if value != 0:
                on = True
                unconfirmed.append(f"{self.describe(i)}: torque still on")
        return (False if on else None if unread else True), unconfirmed

    # ------------------------------------------------------------------ torque
    def torque(
        self, *, handle_signals: bool = True, on_signal: Callable[[str], None] | None = None
    ) -> TorqueContext[DynamixelBus]:
        """Context manager: torque on inside, off on every way out.

        On entry every servo gets its present position (clamped) as goal, then
        torque on, then the Bus Watchdog (``rig.bus.watchdog_ms``). On exit, normal
        or by exception, torque goes off on every servo and the watchdog is
        cleared. With ``handle_signals`` (main thread only) SIGTERM, SIGINT, SIGHUP
        and SIGQUIT are caught while inside: the first calls ``on_signal(name)`` if
        given (e.g. a loop's graceful stop) or else raises KeyboardInterrupt
        (SIGINT) / SafetyStop (the others); a second signal raises at once;
        signals during the torque-off are ignored until it is done.
        """
        return TorqueContext(
            self, is_on=lambda: self.torque_enabled, enable=self.enable_torque,
            disable=self.disable_torque, handle_signals=handle_signals, on_signal=on_signal)

    def enable_torque(self) -> None:
        """Torque on (what entering :meth:`torque` does); DeviceError if not connected."""
        with self._lock:
            if not self._connected:
                raise DeviceError(f"servo bus {self.port} is not connected: call connect()")
            self.torque_control.enable()

    def disable_torque(self) -> list[str]:
        """Torque off on every servo and watchdog cleared; returns the servos that failed.

        A broadcast Sync Write first (reaches every servo at once), then a checked
        write per servo. Never raises for a servo that does not answer.
        """
        with self._lock:
            failed = self.torque_control.disable()
        for f in failed:
            log.error("torque off failed: %s", f)
        return failed
