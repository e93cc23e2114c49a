"""The link: requests out and status replies in over one transport, with the wire budget.

Every request goes out through :meth:`Link.send`, after any goal Sync Write held
back to share its port write, and after the line has gone quiet when a reply
failed (:class:`~handrig.devices.servo.wire.WireBudget`). Single-servo commands are
retried a bounded number of times and must be answered by the servo asked.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from handrig.clock import Clock
from handrig.devices.servo.bus import BusStats
from handrig.devices.servo.codec import (
    BROADCAST_ID,
    HEADER,
    INST_PING,
    INST_READ,
    INST_SYNC_WRITE,
    INST_WRITE,
    StatusPacket,
    build_instruction,
    fast_reply_ids,
    fast_sync_intact,
    parse_status,
    u16,
)
from handrig.devices.servo.registers import ERR_ALERT, Reg, describe_status_error
from handrig.devices.servo.roster import Roster
from handrig.devices.servo.transport import Transport
from handrig.devices.servo.wire import WireBudget
from handrig.errors import DeviceTimeoutError, ProtocolError, ServoFault
from handrig.realtime import CpuPressure

COMMAND_TIMEOUT_S = 0.05  # a single command's reply: RDT 0.5 ms + a 16 ms latency timer, ample
# Commissioning sends ~6 commands per servo: with 20 servos and one reply in five
# lost, 3 attempts would fail a connect more often than not; 8 make it rare.
COMMAND_ATTEMPTS = 8
HOST_STALL_S = 0.001  # a reply waited for ends this late after its deadline, or the host's
# tasks waited this long for a CPU since the request went out: the host held us or the
# reply's writer (an emulator, a USB adapter's driver)
LATE_LOOK_BYTES = 8192  # how much of what comes in after a timeout is looked at for its reply
# A servo begins its reply within microseconds of its Return Delay Time, and a Fast Sync
# Read's blocks follow each other as closely: a reply still not begun this long after the
# latest instant it could have (its wire time and that delay) is not a servo's timing.
HELD_MARGIN_S = 250e-6
UNHEARD_MAX = 256  # unheard requests remembered (see held_test); past it, no held test


class Link:
    """Requests and replies for the servos of ``roster`` over ``transport``.

    ``alerts`` (uint8, rig order): a command answered with the Alert bit raised ORs
    it into the servo's entry, for the fault handler to look at after the read.
    """

    def __init__(
        self, transport: Transport, budget: WireBudget, roster: Roster, clock: Clock,
        stats: BusStats, alerts: np.ndarray, pressure: CpuPressure | None = None,
    ) -> None:
        self.transport = transport
        self.budget = budget
        self.roster = roster
        self.clock = clock
        self.stats = stats
        self.alerts = alerts
        self.held = b""  # a goal Sync Write to send with the next request
        self.sent_s = float("nan")  # when the last write was handed to the OS
        # the host's CPU pressure (None: not looked at; a fake clock's tests)
        self.pressure = pressure
        self._pressure_sent: int | None = None  # its total when the last write went out
        # the request that last timed out with nothing heard (see timed_out): a test its
        # reply passes, what came in since (bounded), and requests sent since
        self._awaited: Callable[[bytes], bool] | None = None
        self._late = bytearray()
        self._sent_since = 0
        # requests (servo IDs in order, reply length) that heard nothing since the last
        # whole reply: a late reply of one would pass a later ask's test (see held_test)
        self._unheard: set[tuple[bytes, int]] = set()

    # ------------------------------------------------------------------ sending
    def hold(self, packet: bytes) -> None:
        """Keep ``packet`` (a goal Sync Write) to go out with the next request."""
        self.held = packet

    @property
    def holding(self) -> bool:
        """Whether a held packet is waiting for a request to take it along."""
        return bool(self.held)

    def send(self, packet: bytes | memoryview, *, answered: bool = True) -> None:
        """Write ``packet`` after any held goal Sync Write, in one port write.
        ``answered=False``: nothing replies to it (a goal Sync Write, a broadcast
        write), so the host's CPU pressure is not looked at for it."""
        data = self.held + bytes(packet) if self.held else packet
        self.held = b""
        self.transport.write(data)
        self.sent_s = now = self.clock.now()
        self.budget.sent(len(data), now)
        if answered and self.pressure is not None:  # after the write: it is out already
            self._pressure_sent = self.pressure.total_us()
        if answered and self._awaited is not None:
            self._sent_since += 1
            if self._sent_since > 1:  # the next request's reply has come or failed since
                self._forget_awaited()

    def quiet_line(self, deadline_s: float | None = None) -> None:
        """Before a request: drop old input; after a failed reply, wait for the line to
        have been quiet ``reply_gap_s`` (at most ``reply_timeout_s``, not past
        ``deadline_s``)."""
        if self.budget.failed_at is None:
            self._drop_input()
            return
        wait = self.budget.take_quiet_wait(self.clock.now(), deadline_s)
        assert wait is not None
        since, most = wait
        self.transport.wait_quiet(self.budget.reply_gap_s, most, since_s=since,
                                  into=self._late_into(), keep=LATE_LOOK_BYTES)
        self._look_at_late()

    def quiet_wait_s(self) -> float:
        """What the quiet after a failed reply adds to a request's wait for the wire
        (:meth:`WireBudget.quiet_wait_s`), counting the late bytes that have come in
        meanwhile: they are taken in first, and the quiet runs from them."""
        if self.budget.failed_at is None:
            return 0.0
        self._drop_input()
        return self.budget.quiet_wait_s(self.clock.now(), self.transport.last_rx_s)

    def request_start(self, now: float) -> float:
        """When a request written at ``now`` would start on the wire."""
        return self.budget.request_start(now, len(self.held), self.transport.last_rx_s)

    def failed(self) -> None:
        """The reply being read failed now."""
        self.budget.failed(self.clock.now())

    def timed_out(self, deadline: float, awaited: Callable[[bytes], bool] | None = None
                  ) -> None:
        """No (whole) reply by ``deadline``: a timeout, and the host's when this process
        only woke ``HOST_STALL_S`` or more after the deadline (the host held it, and the
        reply's writer likely with it: not the bus), or when the host's tasks waited
        ``HOST_STALL_S`` in all for a CPU since the request went out, and a quarter of
        the wait (``pressure``: the reply's writer, an emulator or a driver's work, may
        have been the one held).

        ``awaited``: a test the reply passes (intact, for this request), given only when
        the wait lasted past the latest instant a servo could have sent it (its wire
        time and the Return Delay Time commissioning set, and a margin). If it is not the
        host's by then and that reply still comes in whole before the next request's
        reply is done with (:meth:`late_reply_came`), it was held on its way (by the
        host, an emulator or a USB adapter's latency timer): a servo answers within its
        Return Delay Time or not at all, so the timeout becomes the host's then.
        The line is marked failed."""
        now = self.clock.now()
        self.stats.timeouts += 1
        self._forget_awaited()  # a newer timeout: an older one's reply is no longer sought
        if now - deadline >= HOST_STALL_S or self._host_pressed():
            self.stats.host_timeouts += 1
        else:
            self._awaited = awaited
        self.budget.failed(now)

    def held_test(self, indices: np.ndarray, ids: bytes, data_len: int, expected: int,
                  deadline: float) -> Callable[[bytes], bool] | None:
        """For a Fast Sync Read of the servos ``indices`` (IDs ``ids``, ``data_len`` bytes
        each, ``expected`` bytes in all) of which nothing was heard by ``deadline``: the
        test its whole reply passes (for :meth:`timed_out`), or None when the wait did not
        last ``HELD_MARGIN_S`` past the latest instant a servo could have ended it (the
        request's and the reply's wire time and the servos' Return Delay Time), or when
        the same servos were asked in the same order since the last whole reply and
        heard nothing either (that reply, late, would pass this test too). Asked before
        the timeout marks the line failed."""
        key = (ids, expected)
        asked_before = key in self._unheard or len(self._unheard) >= UNHEARD_MAX
        self._unheard.add(key)
        if asked_before:  # the same servos in the same order, unheard since: undecidable
            return None
        arrival = self.budget.free_at + expected * self.budget.byte_s
        if deadline - arrival < self.roster.latest_reply_delay_s(indices) + HELD_MARGIN_S:
            return None
        valid = np.zeros(len(ids), np.bool_)

        def found(data: bytes) -> bool:
            at = data.find(HEADER)
            while at >= 0:
                raw = data[at: at + expected]
                if (len(raw) == expected and raw[4] == BROADCAST_ID
                        and fast_reply_ids(raw, data_len, len(ids)) == ids
                        and fast_sync_intact(raw, ids, data_len, valid)):
                    return True
                at = data.find(HEADER, at + 1)
            return False

        return found

    def all_heard(self) -> None:
        """A whole reply came in time: replies come in the order asked, so no earlier
        request's reply can still be on its way (see held_test)."""
        self._unheard.clear()

    def late_reply_came(self, reply: bytes) -> bool:
        """A reader recognised ``reply`` as an intact reply to an earlier request: if it
        is the awaited one (see :meth:`timed_out`), that timeout is the host's (True)."""
        if self._awaited is None or not self._awaited(reply):
            return False
        self.stats.host_timeouts += 1
        self._forget_awaited()
        return True

    def _forget_awaited(self) -> None:
        self._awaited = None
        self._late.clear()
        self._sent_since = 0

    def _drop_input(self) -> None:
        """Drop what came in, looking in it for an awaited reply first."""
        self.transport.discard_input(self._late_into(), LATE_LOOK_BYTES)
        self._look_at_late()

    def _late_into(self) -> bytearray | None:
        """Where dropped input is kept to be looked at: only while a reply is awaited."""
        return None if self._awaited is None else self._late

    def _look_at_late(self) -> None:
        if self._late and self.late_reply_came(bytes(self._late)):
            self.stats.late_replies += 1  # recognised and dropped

    def _host_pressed(self) -> bool:
        """Whether the host's tasks waited for a CPU, since the request went out, at
        least ``HOST_STALL_S`` and a quarter of the wait (a command's 50 ms wait on a
        busy host always sees some: that alone does not make an unplugged servo the
        host's)."""
        if self.pressure is None or self._pressure_sent is None:
            return False
        total = self.pressure.total_us()
        if total is None:
            return False
        waited_s = self.clock.now() - self.sent_s
        return total - self._pressure_sent >= max(HOST_STALL_S, 0.25 * waited_s) * 1e6

    def sync_write(self, reg: Reg, values: list[int]) -> None:
        """One broadcast Sync Write of ``reg`` (one value per servo, rig order)."""
        params = u16(reg.address) + u16(reg.size) + b"".join(
            bytes((sid,)) + reg.encode(v) for sid, v in zip(self.roster.ids, values, strict=True))
        self.send(build_instruction(BROADCAST_ID, INST_SYNC_WRITE, params), answered=False)

    # ------------------------------------------------------------------ replies
    def next_status(self, deadline: float, *, answer: bool = False) -> StatusPacket | None:
        """The next status packet that passes its CRC before ``deadline``. Packets failing
        it are counted and skipped; none in time counts a timeout, marks the line
        failed (a late reply may still arrive) and returns None. ``answer``: the first
        answer to a state read (the transport counts it when none comes)."""
        while True:
            raw = self.transport.read_packet(deadline, answer=answer)
            if raw is None:
                self.timed_out(deadline)
                return None
            try:
                return parse_status(raw)
            except ProtocolError:
                self.stats.crc_errors += 1

    def read_reply(self, n: int, deadline: float) -> bytes:
        """Up to ``n`` bytes of a reply: its start may take until ``deadline`` (the wire
        can still be busy with earlier packets); once it has started, a gap of
        ``reply_gap_s`` ends it (counted from the start, not from the request)."""
        t = self.transport
        head = t.read_exact(min(n, 7), deadline)
        if len(head) < min(n, 7):
            return head
        return head + t.read_exact(n - len(head), deadline, gap_s=self.budget.reply_gap_s)

    def broadcast_ping(self, wait_s: float = 0.1) -> dict[int, int]:
        """{ID: model number} of every servo answering a broadcast ping within ``wait_s``."""
        t = self.transport
        self.quiet_line()
        self.send(build_instruction(BROADCAST_ID, INST_PING))
        deadline = self.clock.now() + wait_s
        found: dict[int, int] = {}
        while (raw := t.read_packet(deadline)) is not None:
            try:
                status = parse_status(raw)
            except ProtocolError:
                continue
            if len(status.params) >= 2:
                found[status.servo_id] = status.params[0] | status.params[1] << 8
        return found

    # ------------------------------------------------------------------ commands
    def transact(
        self, packet: bytes, servo_id: int, *, timeout_s: float = COMMAND_TIMEOUT_S,
        attempts: int = COMMAND_ATTEMPTS, n_params: int | None = None,
    ) -> StatusPacket | None:
        """Send ``packet`` and return ``servo_id``'s status reply, or None after ``attempts``.

        ``n_params``: the reply's parameter count when it succeeds (a status with
        another count and no error is a reply to something else, e.g. late).
        """
        for attempt in range(attempts):
            if attempt:
                self.stats.retries += 1
            self.quiet_line()
            self.send(packet)
            deadline = self.clock.now() + timeout_s
            while (status := self.next_status(deadline)) is not None:
                if status.servo_id != servo_id or (
                    n_params is not None and not status.error & 0x7F
                    and len(status.params) != n_params
                ):
                    self.stats.malformed += 1
                    continue
                return status
        return None

    def command(
        self, index: int, instruction: int, params: bytes, what: str, n_params: int = 0,
        attempts: int = COMMAND_ATTEMPTS,
    ) -> StatusPacket:
        """One instruction to servo ``index`` that must be answered without an error number."""
        r = self.roster
        sid = r.ids[index]
        status = self.transact(build_instruction(sid, instruction, params), sid,
                               n_params=n_params, attempts=attempts)
        if status is None:
            raise DeviceTimeoutError(
                f"{r.describe(index)} did not answer {what} {r.where()} after "
                f"{attempts} attempts: check power, cable and ID"
            )
        if status.error & 0x7F:
            raise ServoFault(
                f"{r.describe(index)} refused {what}: {describe_status_error(status.error)}",
                servo_id=sid, bits=status.error,
            )
        if status.error & ERR_ALERT:
            self.alerts[index] |= ERR_ALERT
        return status

    def read_register(self, index: int, reg: Reg) -> int:
        """Read one control-table item of servo ``index`` (rig order)."""
        status = self.command(
            index, INST_READ, u16(reg.address) + u16(reg.size), f"a read of {reg.name}",
            n_params=reg.size,
        )
        if len(status.params) < reg.size:
            self.stats.malformed += 1
            raise ProtocolError(
                f"{self.roster.describe(index)} sent {len(status.params)} bytes for {reg.name} "
                f"({reg.size} expected) {self.roster.where()}"
            )
        return reg.decode(status.params)

    def write_register(self, index: int, reg: Reg, value: int,
                       attempts: int = COMMAND_ATTEMPTS) -> None:
        """Write one control-table item of servo ``index`` and check the reply."""
        self.command(
            index, INST_WRITE, u16(reg.address) + reg.encode(value),
            f"a write of {reg.name} = {value}", attempts=attempts,
        )
