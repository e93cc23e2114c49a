"""The state reader: one present-state read with its retries, stale marking and checks.

A read (or retry) whose request and reply could not both be on the wire before
its deadline is not sent: on a half-duplex bus its reply would still be arriving
when the caller's next goals go out. Failed servos are retried while the
deadline allows; a Fast Sync Read reply stops at the first servo that does not
answer, so a retry asks the rest first and the one where it stopped last.

One silent servo must cost that servo only. The servo where a chain's reply
was cut short is a suspect; after ``SILENT_AFTER`` reads in a row as one it is
asked at the end of the chain (where its silence costs the others nothing, and
its answer, when it comes back, is read at once) and not retried. A read of a
part that got nothing at all starts its chain one servo later next time (whole
reads rotate anyway), so a silent first servo is found out too. When every
servo asked is a suspect (the bus, not a servo, is quiet) all are asked.
"""

from __future__ import annotations

import numpy as np

from handrig.clock import Clock
from handrig.devices.servo.bus import BusStats, FaultPolicy, ServoState
from handrig.devices.servo.fast_read import WHOLE, FastSyncRead, Order
from handrig.devices.servo.faults import FaultHandler
from handrig.devices.servo.link import Link
from handrig.devices.servo.readings import Readings, ReadPlan
from handrig.devices.servo.registers import Reg
from handrig.devices.servo.sync_read import RegisterSweep, SyncRead
from handrig.devices.servo.wire import read_bytes, wire_time_s

HOUSEKEEPING_FORCE_S = 1.0  # housekeeping due this long runs where the wire has room
SMOOTHING = 0.125  # weight of the newest figure in what a read learns (retries, housekeeping)
ATTEMPT_EXTRA_MAX_S = 0.005  # an answer later than this beyond the wire is not learnt
SILENT_AFTER = 2  # reads in a row a chain stopped at a servo: it goes to the chain's end


class StateReader:
    """Present-state reads: Fast Sync Read, with a fallback to Sync Read for good after
    ``policy.fast_failures_before_fallback`` failures in a row while Sync Read works.

    ``temperature_every``: every that many reads, when the deadline leaves time,
    the Bus Watchdogs (torque on) and then the temperatures are read too (0: never).
    :meth:`housekeeping` does the same between state reads (the loop calls it in
    cycles without a read, where the wire has room for it).
    """

    def __init__(
        self, link: Link, readings: Readings, plan: ReadPlan, fast: FastSyncRead,
        sync: SyncRead, sweep: RegisterSweep, faults: FaultHandler, policy: FaultPolicy,
        stats: BusStats, clock: Clock, temperature_every: int,
    ) -> None:
        self.link = link
        self.readings = readings
        self.plan = plan
        self.fast = fast
        self.sync = sync
        self.sweep = sweep
        self.faults = faults
        self.policy = policy
        self.stats = stats
        self.clock = clock
        self.temperature_every = int(temperature_every)
        self._next_temperature_read = 0
        self._fast_fail_run = 0
        self._parts: dict[tuple[int, int], np.ndarray] = {}
        n = readings.n
        self.suspect = np.zeros(n, np.int64)  # reads in a row a chain stopped at the servo
        self._suspects = False  # any suspect at all (the usual read skips the checks)
        self._shift: dict[tuple[int, int], int] = {}  # a part's chain start (see above)
        baud = link.budget.baud
        # a temperature Fast Sync Read (1 byte per servo)
        self._temperature_wire_s = wire_time_s(read_bytes(n, 1, True), baud) + 0.0005
        # how long housekeeping has taken here (its replies come no sooner than the wire
        # allows, and later from a slow adapter or a busy emulator): it runs only where
        # that much room is left, unless it has been due for HOUSEKEEPING_FORCE_S
        self._housekeeping_s = 0.0
        self._housekeeping_due_at: float | None = None
        # how much longer than its wire time an answered request has taken here (the
        # host's and the adapter's or emulator's share): a retry starts only with room
        # for that too, else it would run past the read's deadline into the next write
        self._attempt_extra_s = 0.0
        # a read's default budget is never shorter than one reply on the wire plus slack
        self._min_budget_s = 1.5 * wire_time_s(read_bytes(n, plan.data_len, True), baud) + 0.001
        self.last_whole = False
        """Whether the last read got every servo at once with no Alert bit raised (the
        short way: one compiled pass decoded the reply into the returned state)."""

    def read_wire_s(self, n: int) -> float:
        """Wire time of a present-state read of ``n`` servos: the request and every reply."""
        return read_bytes(n, self.plan.data_len, self.plan.fast) * self.link.budget.byte_s

    def read(self, deadline_s: float | None, part: tuple[int, int] | None = None,
             patient: bool = False) -> ServoState:
        """One present-state read (see :meth:`handrig.devices.servo.DynamixelBus.read_state`)."""
        if part is not None and part[1] > 1:
            return self._read_part(part, deadline_s)
        begun = self._begin(self.readings.n, deadline_s)
        if isinstance(begun, ServoState):
            return begun
        deadline_s = begun
        if self._attempts(deadline_s, patient) and not (
                self.temperature_every and self.stats.reads >= self._next_temperature_read):
            return self.readings.take_whole(self.fast.whole_at)
        return self._finish(deadline_s)

    def _begin(self, k: int, deadline_s: float | None) -> float | ServoState:
        """The start of a read of ``k`` servos: its deadline (None: the default budget
        from when the wire is free of the goal Sync Write just sent), or, when its
        request and replies cannot be on the wire by then, the state of a read not sent
        (counted as skipped)."""
        now = self.clock.now()
        start = self.link.request_start(now)
        if deadline_s is None:
            deadline_s = start + max(self.policy.read_budget_s, self._min_budget_s)
        elif start + self.read_wire_s(k) > deadline_s:
            self.faults.read_skipped(self.read_wire_s(k), deadline_s - now)
            return self.readings.unread(now)
        self.faults.read_sent()
        self.stats.reads += 1
        self.readings.start_read()
        self.last_whole = False
        return deadline_s

    def part_indices(self, part: tuple[int, int]) -> np.ndarray:
        """The servos of part ``i`` of ``m`` (rig indices ``i, i + m, i + 2m, ...``)."""
        i, m = part
        if not 0 < m <= self.readings.n:
            raise ValueError(f"read parts must be 1..{self.readings.n}, got {m}")
        key = (i % m, m)
        got = self._parts.get(key)
        if got is None:
            got = self._parts[key] = np.arange(key[0], self.readings.n, m, dtype=np.intp)
        return got

    def _read_part(self, part: tuple[int, int], deadline_s: float | None) -> ServoState:
        """A read of one part of the servos: the same checks, retries, stale marking and
        silence tiers as a whole read, for the servos it asks; the others keep their
        last reading and are not marked stale by it."""
        indices = self.part_indices(part)
        begun = self._begin(len(indices), deadline_s)
        if isinstance(begun, ServoState):
            return begun
        deadline_s = begun
        shift = self._shift.get(part, 0)
        pending = self._chain(np.roll(indices, -shift) if shift else indices)
        for attempt in range(self.policy.read_retries + 1):
            if attempt:
                if (self.link.request_start(self.clock.now())
                        + self._retry_s(len(pending)) > deadline_s):
                    break
                self.stats.retries += 1
            self._attempt(pending, None, deadline_s)
            if self.readings.fresh[pending].all():  # every servo asked answered
                if self._suspects:
                    self._blame(pending)
                break
            if not self._blame(pending) and not attempt:
                self._shift[part] = (shift + 1) % len(indices)
            left = self._retry_chain(pending)
            if not left.size:
                break
            # the first servo that did not answer goes last: in a Fast Sync Read the
            # servos after a silent one in the chain fail with it
            pending = np.roll(left, -1)
        return self._finish(deadline_s, indices)

    def _attempts(self, deadline_s: float, patient: bool = False) -> bool:
        """The read and its retries; True when it was whole."""
        first = self.fast.orders[self.stats.reads % len(self.fast.orders)]
        pending = self._chain(first.indices)
        order: Order | None = first if pending is first.indices else None
        for attempt in range(self.policy.read_retries + 1):
            if attempt:
                start = self.link.request_start(self.clock.now())
                if start + self._retry_s(len(pending)) > deadline_s:
                    break
                self.stats.retries += 1
            if self._attempt(pending, order, deadline_s, patient) == WHOLE:
                self.last_whole = True
                if self._suspects:
                    self.suspect[:] = 0
                    self._suspects = False
                return True
            self._blame(pending)
            left = self._retry_chain(pending)
            if not left.size:
                break
            pending = np.roll(left, -1)
            order = None
        return False

    def _chain(self, indices: np.ndarray) -> np.ndarray:
        """``indices`` (as ordered) with the servos that stopped answering at the end
        (counted in ``chain_ends``); ``indices`` itself when none did."""
        if not self._suspects:
            return indices
        out = self.suspect[indices] >= SILENT_AFTER
        if not out.any() or out.all():
            return indices
        self.stats.chain_ends += 1
        return np.concatenate((indices[~out], indices[out]))

    def _retry_chain(self, asked: np.ndarray) -> np.ndarray:
        """The servos of the chain ``asked`` worth a retry: those without a reading,
        less those that stopped answering when others did answer."""
        fresh = self.readings.fresh[asked]
        left = asked[~fresh]
        if not fresh.any():
            return left  # nobody answered: the bus, not a servo, is quiet
        return left[self.suspect[left] < SILENT_AFTER]

    def _blame(self, asked: np.ndarray) -> bool:
        """After a read of the chain ``asked``: the first servo without a reading, where
        a reply was cut short, is a suspect once more; those that answered are cleared.
        False when nobody answered (then nobody is blamed: the bus may be quiet)."""
        fresh = self.readings.fresh[asked]
        self.suspect[asked[fresh]] = 0
        if fresh.all():
            self._suspects = self._suspects and bool(self.suspect.any())
            return True
        if not fresh.any():
            return False
        self.suspect[asked[int(np.argmin(fresh))]] += 1
        self._suspects = True
        return True

    def _retry_s(self, k: int) -> float:
        """The time a retry of ``k`` servos is expected to take: its wire time and what
        answered requests have taken here beyond theirs."""
        return self.read_wire_s(k) + self._attempt_extra_s

    def _answered(self, start_s: float, k: int) -> None:
        """A request for ``k`` servos sent at ``start_s`` was answered now."""
        extra = max(0.0, self.clock.now() - start_s - self.read_wire_s(k))
        if extra <= ATTEMPT_EXTRA_MAX_S:  # longer: a stalled host, not the bus's way
            self._attempt_extra_s += SMOOTHING * (extra - self._attempt_extra_s)

    def _attempt(self, indices: np.ndarray, order: Order | None, deadline_s: float,
                 patient: bool = False) -> int:
        """One read of ``indices``: what :meth:`FastSyncRead.read` returns (Sync Read: 1/0).
        ``patient``: its replies are waited for until ``deadline_s``, not only until the
        reply deadline their wire time gives."""
        start = self.clock.now()
        deadline = (deadline_s if patient
                    else min(deadline_s, self.link.budget.reply_deadline(start)))
        if not self.plan.fast:
            got = int(self.sync.read(indices, deadline))
            if got:
                self._answered(start, len(indices))
            return got
        got = self.fast.read(indices, deadline, order)
        if got:
            self._fast_fail_run = 0
            self._answered(start, len(indices))
            return got
        self._fast_fail_run += 1
        if self._fast_fail_run >= self.policy.fast_failures_before_fallback:
            self._fast_fail_run = 0
            deadline = min(deadline_s, self.link.budget.reply_deadline(self.clock.now()))
            if self.sync.read(indices, deadline):
                self.plan.fall_back(
                    f"{self.policy.fast_failures_before_fallback} Fast Sync Reads "
                    "failed in a row while Sync Read works")
                return 1
        return got

    def _housekeeping_due(self) -> bool:
        return bool(self.temperature_every) and self.stats.reads >= self._next_temperature_read

    def _housekeeping_fits(self, deadline_s: float) -> bool:
        """Whether the housekeeping due now may run before ``deadline_s``: the wire
        must carry it, and the time it has taken here must fit too, unless it has been
        due for ``HOUSEKEEPING_FORCE_S`` (it is not put off for ever)."""
        now = self.clock.now()
        left = deadline_s - now
        if left <= self._temperature_wire_s:
            return False
        if self._housekeeping_due_at is None:
            self._housekeeping_due_at = now
        return (left > self._housekeeping_s
                or now - self._housekeeping_due_at >= HOUSEKEEPING_FORCE_S)

    def _finish(self, deadline_s: float, asked: np.ndarray | None = None) -> ServoState:
        """Stale marking, alerts, housekeeping and the stale-run check of a read
        (``asked``: the servos a read of a part asked for)."""
        now = self.clock.now()
        r = self.readings
        whole = self.last_whole
        if whole or (r.fresh.all() if asked is None else r.fresh[asked].all()):
            self.link.budget.reply_in(now)
            self.link.all_heard()
        stale = r.mark(now, asked)
        if not whole and r.status_err.any():
            self.faults.alerts_raised()
        if self._housekeeping_due() and self._housekeeping_fits(deadline_s):
            self._next_temperature_read = self.stats.reads + self.temperature_every
            self._housekeeping(deadline_s)
        # where a chain stopped (Fast Sync Read): the servos blamed and not heard since
        stopped = self.suspect > 0 if self.plan.fast else None
        return r.snapshot(now, stale, r.hw_err.copy(), asked, stopped)

    def housekeeping(self, deadline_s: float) -> bool:
        """The housekeeping reads in a cycle without a state read, when due and when the
        wire can carry them by ``deadline_s``; True if they ran."""
        if not self._housekeeping_due() or not self._housekeeping_fits(deadline_s):
            return False
        self._next_temperature_read = self.stats.reads + self.temperature_every
        self._housekeeping(deadline_s)
        return True

    def _housekeeping(self, deadline_s: float) -> None:
        """With torque on, the Bus Watchdogs first, then the temperatures if the read's
        deadline leaves time for them."""
        start = self.clock.now()
        self._housekeeping_due_at = None
        try:
            self._housekeeping_reads(deadline_s)
        finally:
            took = self.clock.now() - start
            est = self._housekeeping_s  # a long one counts at once, short ones slowly
            self._housekeeping_s = took if took > est else est + SMOOTHING * (took - est)

    def _housekeeping_reads(self, deadline_s: float) -> None:
        np.greater_equal(self.suspect, SILENT_AFTER, out=self.sweep.last)  # asked last
        if self.faults.torque_on and self.faults.watchdog_ms:
            self.faults.check_watchdogs(deadline_s)
            if deadline_s - self.clock.now() <= self._temperature_wire_s:
                return
        temps = self.readings.temperatures_c
        for i, value in enumerate(self.sweep.read(Reg.PRESENT_TEMPERATURE, deadline_s)):
            if value is not None:
                temps[i] = value
