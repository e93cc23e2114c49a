"""One Fast Sync Read of the servos' present state, and late replies told apart.

Protocol 2.0 has no sequence numbers, so each read asks for the servos in another
order (up to ``ORDERS`` of them, rig order first): a reply arriving after its read
gave up names the servos in its own order and is recognised as late instead of
being taken for a later read's. Only a reply a multiple of ``ORDERS`` reads late
could pass.

The usual reply (every servo, intact, no error) is checked and decoded in one
compiled pass (:func:`handrig.devices.servo.codec.fast_sync_whole`) into a state allocated
while the request and reply were on the wire; a damaged or partial one yields
the servos whose running CRCs check (:func:`handrig.devices.servo.codec.fast_sync_take`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handrig.devices.servo import codec
from handrig.devices.servo.bus import BusStats
from handrig.devices.servo.link import Link
from handrig.devices.servo.readings import Readings, ReadPlan
from handrig.devices.servo.roster import Roster
from handrig.errors import ProtocolError

ORDERS = 64  # servo orders a Fast Sync Read cycles through (late replies are told apart)
ORDERS_KEPT = 256  # orders of parts and retries kept once built
# Replies are polled for (spin_s) from spin_s before the instant the wire delivers
# them until REPLY_POLL_AFTER_S after it (the pty or USB hand-over and the servos'
# own lateness), then waited for asleep.
REPLY_POLL_AFTER_S = 300e-6
INSTRUCTION_ERROR = 2  # ERR number: the servo does not know the instruction
LATE_REPLIES_MAX = 4  # late replies dropped within one read before giving up
NONE, SOME, WHOLE = 0, 1, 2  # what a read got: nothing, some servos, every servo at once


@dataclass(frozen=True)
class Order:
    """The servos of one read, in the order asked: rig indices, IDs, the request."""

    indices: np.ndarray  # (n,) intp
    ids: np.ndarray  # (n,) uint8
    request: bytes


def make_orders(roster: Roster, plan: ReadPlan, count: int = ORDERS) -> list[Order]:
    """Up to ``count`` distinct orders of every servo: rotations first, then shuffles."""
    n = roster.n
    orders: list[Order] = []
    seen: set[bytes] = set()
    rng = np.random.default_rng(0)
    for attempt in range(4 * count):
        if len(orders) >= count:
            break
        idx = np.roll(np.arange(n), -attempt) if attempt < n else rng.permutation(n)
        ids = bytes(roster.ids[int(i)] for i in idx)
        if ids in seen:
            continue
        seen.add(ids)
        orders.append(Order(idx, np.frombuffer(ids, np.uint8), codec.read_request(
            codec.INST_FAST_SYNC_READ, plan.address, plan.data_len, ids)))
    return orders


class FastSyncRead:
    """Fast Sync Reads of the present state into ``readings``.

    ``spin_s``: poll for the reply from that long before the wire would deliver
    it (0: always sleep until it comes)."""

    def __init__(
        self, roster: Roster, link: Link, readings: Readings, plan: ReadPlan, stats: BusStats,
        spin_s: float,
    ) -> None:
        self.roster = roster
        self.link = link
        self.readings = readings
        self.plan = plan
        self.stats = stats
        self.spin_s = spin_s
        self.orders = make_orders(roster, plan)
        self._whole_len = codec.fast_reply_len(plan.data_len, roster.n)
        self._valid = np.zeros(roster.n, np.bool_)
        self._orders_of: dict[bytes, Order] = {}  # see _order_of
        self.whole_at = 0.0  # when the last whole reply was decoded

    def read(self, indices: np.ndarray, deadline: float, order: Order | None = None) -> int:
        """One Fast Sync Read of ``indices`` (``order``: every servo, as that order asks).

        Returns WHOLE when the reply was whole (every servo, intact, no error, no
        Alert: the state is ready in ``readings``), SOME when some servo gave a valid
        reading, NONE when none did.
        """
        if order is None:
            order = self._order_of(indices)
            whole_ok = False
        else:
            whole_ok = True
        expected = self._whole_len if whole_ok else codec.fast_reply_len(
            self.plan.data_len, len(indices))
        self.link.quiet_line(deadline)
        self.link.send(order.request)
        out = self.readings.prepare_whole() if whole_ok else None
        raw = self._receive(expected, deadline, order)
        if raw is None:
            return NONE
        if out is not None and (alerts := self._take_whole(raw, order, out)) >= 0:
            return WHOLE if alerts == 0 else SOME
        raw, late = self._drop_late(raw, order, expected, deadline)
        if raw is None:
            return NONE
        if late and out is not None and (alerts := self._take_whole(raw, order, out)) >= 0:
            self.readings.recount_whole()  # the late reply counted
            return WHOLE if alerts == 0 else SOME
        return SOME if self._take_partial(raw, order, expected) else NONE

    def _order_of(self, indices: np.ndarray) -> Order:
        """The order asking ``indices`` as they are ordered: built once, then kept (a
        read of a part asks the same servos each time; retries ask fewer)."""
        key = indices.tobytes()
        order = self._orders_of.get(key)
        if order is None:
            ids = bytes(self.roster.ids[int(i)] for i in indices)
            order = Order(indices.copy(), np.frombuffer(ids, np.uint8), codec.read_request(
                codec.INST_FAST_SYNC_READ, self.plan.address, self.plan.data_len, ids))
            if len(self._orders_of) < ORDERS_KEPT:
                self._orders_of[key] = order
        return order

    def _receive(self, expected: int, deadline: float, order: Order) -> bytes | None:
        """The reply (up to ``expected`` bytes) of the servos ``order`` asks, or None when none
        came (a timeout: its reply is looked for in what comes in late) or it is not a
        Fast Sync Read reply at all (counted; a single servo's error status may switch to
        Sync Read)."""
        t = self.link.transport
        spin_from = None
        spin_until = np.inf
        if self.spin_s > 0:
            # the reply cannot end before the wire has carried the request and the reply
            budget = self.link.budget
            arrival = budget.free_at + expected * budget.byte_s
            spin_from = arrival - self.spin_s
            spin_until = arrival + REPLY_POLL_AFTER_S
        head = t.read_exact(7, deadline, spin_from, spin_until_s=spin_until, answer=True)
        if len(head) < 7:
            # nothing heard: if the reply still comes whole, late enough, it was held on
            # its way (Link.held_test, Link.timed_out)
            held = None if head else self.link.held_test(
                order.indices, order.ids.tobytes(), self.plan.data_len, expected, deadline)
            self.link.timed_out(deadline, held)
            return None
        if head[:4] != codec.HEADER:
            self.stats.malformed += 1
            self.link.failed()
            return None
        total = codec.packet_length(head)
        if head[4] != codec.BROADCAST_ID:
            self._single_status(head, total, deadline)
            return None
        if total != expected:
            self.stats.malformed += 1
        return head + t.read_exact(min(total, expected) - 7, deadline, spin_from,
                                   self.link.budget.reply_gap_s, spin_until)

    def _single_status(self, head: bytes, total: int, deadline: float) -> None:
        """A single servo's status instead of the reply: an error report or a wrong reply."""
        rest = self.link.transport.read_exact(total - 7, deadline) if total <= 1024 else b""
        try:
            status = codec.parse_status(head + rest)
        except ProtocolError:
            self.stats.crc_errors += 1
            return
        self.stats.malformed += 1
        if status.error & 0x7F == INSTRUCTION_ERROR:
            self.plan.fall_back(
                f"servo {status.servo_id} answered 'instruction error' to Fast Sync Read")

    def _take_whole(self, raw: bytes, order: Order, out: tuple[np.ndarray, np.ndarray]) -> int:
        """The whole-reply kernel's answer: Alert bits raised, or < 0 (nothing taken)."""
        r = self.readings
        now = self.link.clock.now()
        alerts = codec.fast_sync_whole(
            np.frombuffer(raw, np.uint8), self.plan.data_len, order.indices, order.ids,
            self.roster.scale, r.latest, r.status_err, r.stale_run, r.fresh, now, *out)
        if alerts >= 0:
            self.whole_at = now
            self.link.budget.reply_in(now)  # the reply is in: the wire is quiet
            self.link.all_heard()
        return int(alerts)

    def _drop_late(
        self, raw: bytes, order: Order, expected: int, deadline: float
    ) -> tuple[bytes | None, bool]:
        """Skip intact replies to earlier reads (they name our servos in another order);
        returns the reply for this read (None: rejected whole) and whether one was late."""
        ids = order.ids.tobytes()
        late = False
        for _ in range(LATE_REPLIES_MAX):
            named = codec.fast_reply_ids(raw, self.plan.data_len, len(ids))
            if not named or named == ids[: len(named)]:
                return raw, late
            if sorted(named) == sorted(ids) and codec.fast_sync_intact(
                    raw, named, self.plan.data_len, self._valid):
                self.stats.late_replies += 1
                self.link.late_reply_came(raw)  # held on its way, if the one that timed out
                raw = self.link.read_reply(expected, deadline)
                late = True
                continue
            self.stats.malformed += 1
            self.link.failed()
            return None, late
        return None, late

    def _take_partial(self, raw: bytes, order: Order, expected: int) -> bool:
        if len(raw) < expected:  # cut short: a servo in the chain did not answer
            self.stats.timeouts += 1
            self.stats.partial_replies += 1
            self.link.failed()
        r = self.readings
        complete, taken, refused = codec.fast_sync_take(
            np.frombuffer(raw, np.uint8), self.plan.data_len, order.indices, order.ids,
            self.roster.scale, r.latest, r.status_err, r.fresh, self._valid)
        if complete == 0:
            return False
        bad = complete - int(np.count_nonzero(self._valid[:complete]))
        self.stats.crc_errors += bad  # a bad CRC or a block naming the wrong servo
        self.stats.status_errors += refused
        return taken > 0
