"""Plain Sync Read of the present state (the fallback), and one-byte items of every servo.

A Sync Read gets one status packet per servo, in the order asked; a servo that
does not answer leaves the others' replies intact.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from handrig.devices.servo import codec
from handrig.devices.servo.bus import BusStats
from handrig.devices.servo.link import Link
from handrig.devices.servo.readings import Readings, ReadPlan
from handrig.devices.servo.registers import Reg
from handrig.devices.servo.roster import Roster
from handrig.errors import ProtocolError


class SyncRead:
    """Sync Reads of the present state into ``readings``."""

    def __init__(
        self, roster: Roster, link: Link, readings: Readings, plan: ReadPlan, stats: BusStats
    ) -> None:
        self.roster = roster
        self.link = link
        self.readings = readings
        self.plan = plan
        self.stats = stats

    def read(self, indices: np.ndarray, deadline: float) -> bool:
        """One Sync Read of ``indices``; True if some servo gave a valid reading."""
        r, plan, stats = self.readings, self.plan, self.stats
        ids = [self.roster.ids[int(i)] for i in indices]
        self.link.quiet_line(deadline)
        self.link.send(codec.read_request(
            codec.INST_SYNC_READ, plan.address, plan.data_len, bytes(ids)))
        want = {sid: int(i) for sid, i in zip(ids, indices, strict=True)}
        got = 0
        while got < len(ids):
            status = self.link.next_status(deadline, answer=got == 0)
            if status is None:
                break
            index = want.pop(status.servo_id, None)
            if index is not None and status.error & 0x7F:
                stats.status_errors += 1
                r.status_err[index] = status.error
                continue
            if index is None or len(status.params) < plan.data_len:
                stats.malformed += 1
                continue
            codec.decode_reading(np.frombuffer(status.params, np.uint8), 0, plan.data_len,
                                 index, self.roster.scale, r.latest)
            r.status_err[index] = status.error
            r.fresh[index] = True
            got += 1
        return got > 0


class RegisterSweep:
    """A one-byte control-table item of every servo in one request (Fast Sync Read,
    or Sync Read after a fallback)."""

    def __init__(self, roster: Roster, link: Link, plan: ReadPlan, stats: BusStats) -> None:
        self.roster = roster
        self.link = link
        self.plan = plan
        self.stats = stats
        self._valid = np.zeros(roster.n, np.bool_)
        # servos asked at the end of the chain (the state reader's silent ones): a Fast
        # Sync Read reply stops at a servo that does not answer, and those after it
        # would go unread too
        self.last = np.zeros(roster.n, np.bool_)
        self._turn = 0  # sweeps asked: turns their order (_order)

    def _order(self) -> tuple[np.ndarray, bytes]:
        """Rig indices in the order asked, and their IDs: turned by one servo at each
        sweep (those in ``last`` stay last). A one-byte reply does not say which item it
        holds, so the order is what tells one sweep's late reply from the next's (the
        Bus Watchdog sweep and the temperature sweep run back to back)."""
        r = self.roster
        first = np.flatnonzero(~self.last)
        self._turn += 1
        if first.size > 1:
            first = np.roll(first, -(self._turn % first.size))
        order = np.concatenate((first, np.flatnonzero(self.last)))
        return order, bytes(r.ids[int(i)] for i in order)

    def read(self, reg: Reg, deadline_s: float) -> list[int | None]:
        """``reg`` of every servo (rig order); None for a servo without a valid reply."""
        link = self.link
        deadline = min(deadline_s, link.budget.reply_deadline(link.clock.now()))
        link.quiet_line(deadline)
        held: Callable[[bytes], bool] | None = None  # a test of its reply, if nothing came
        if self.plan.fast:
            out, held = self._fast(reg, deadline)
        else:
            out = self._sync(reg, deadline)
        if None in out:
            link.timed_out(deadline, held)
        else:
            link.all_heard()
        return out

    def _fast(self, reg: Reg, deadline: float
              ) -> tuple[list[int | None], Callable[[bytes], bool] | None]:
        """The values, and the test of the reply's late arrival when nothing was heard
        (Link.held_test)."""
        r = self.roster
        order, ids = self._order()
        expected = codec.fast_reply_len(1, r.n)
        self.link.send(codec.read_request(codec.INST_FAST_SYNC_READ, reg.address, 1, ids))
        raw = self.link.read_reply(expected, deadline)
        held = None if raw else self.link.held_test(order, ids, 1, expected, deadline)
        codec.fast_sync_check(np.frombuffer(raw, np.uint8), np.frombuffer(ids, np.uint8),
                              1, self._valid)
        out: list[int | None] = [None] * r.n
        for k in np.flatnonzero(self._valid).tolist():
            err, _, data = codec.fast_block(raw, k, 1)
            if not err & 0x7F:
                out[int(order[k])] = reg.decode(data)
        return out, held

    def _sync(self, reg: Reg, deadline: float) -> list[int | None]:
        r = self.roster
        _, ids = self._order()
        self.link.send(codec.read_request(codec.INST_SYNC_READ, reg.address, 1, ids))
        out: list[int | None] = [None] * r.n
        for _ in range(r.n):
            packet = self.link.transport.read_packet(deadline)
            if packet is None:
                break
            try:
                status = codec.parse_status(packet)
            except ProtocolError:
                self.stats.crc_errors += 1
                continue
            index = r.index_of_id.get(status.servo_id)
            if index is not None and status.params and not status.error & 0x7F:
                out[index] = reg.decode(status.params[:1])
        return out
