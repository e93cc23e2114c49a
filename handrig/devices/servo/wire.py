"""The wire budget: when the half-duplex line is free, and whether a read fits a deadline.

Times are seconds on the bus clock; the line carries 10 bits per byte (8N1).
After a failed reply the line must be quiet ``reply_gap_s`` from the failure or
from the last byte received, whichever is later, before the next request: a late
reply still on the wire would collide with it.
"""

from __future__ import annotations

import numpy as np

from handrig.devices.servo.codec import fast_reply_len

BITS_PER_BYTE = 10  # 8N1 on the wire


def wire_time_s(n_bytes: int, baud: int) -> float:
    """Time ``n_bytes`` take on the wire at ``baud`` (10 bits per byte)."""
    return n_bytes * BITS_PER_BYTE / baud


def goal_write_bytes(n_servos: int) -> int:
    """Bytes of a Sync Write of Goal Position to ``n_servos``: 14 + 5N (REFERENCE.md
    section 3: header, id, length, instruction, address, data length, CRC; per servo
    its id and 4 data bytes)."""
    return 14 + 5 * n_servos


def cycle_bytes(n_servos: int, data_len: int = 4) -> int:
    """Bytes per write + Fast Sync Read cycle (REFERENCE.md section 3).

    Sync Write of Goal Position 14 + 5N, Fast Sync Read instruction 14 + N, its
    reply 8 + (data_len + 4) N (8 + 8N for the 4-byte position).
    """
    return goal_write_bytes(n_servos) + read_bytes(n_servos, data_len, True)


def read_bytes(n_servos: int, data_len: int, fast: bool) -> int:
    """Bytes of a present-state read of ``n_servos``: the request and every reply
    (a Sync Read gets one 11 + data_len byte status per servo)."""
    if fast:
        return 14 + n_servos + fast_reply_len(data_len, n_servos)
    return 14 + n_servos + (11 + data_len) * n_servos


class WireBudget:
    """What the host knows about the line: when what it sent is off the wire, when it
    last sent, and since when a failed reply asks for a quiet line.

    ``reply_gap_s``: a reply that stops flowing this long is over, and the quiet
    time after a failure; ``reply_timeout_s``: the longest wait for one reply.
    """

    def __init__(self, baud: int, reply_gap_s: float, reply_timeout_s: float) -> None:
        self.baud = baud
        self.byte_s = BITS_PER_BYTE / baud
        self.reply_gap_s = reply_gap_s
        self.reply_timeout_s = reply_timeout_s
        self.free_at = -np.inf  # when the wire is expected to be quiet again
        self.last_tx_s = -np.inf  # when the host last put bytes on the bus
        # when a reply failed (None: none did since the last request)
        self.failed_at: float | None = None

    def sent(self, n_bytes: int, now: float) -> None:
        """``n_bytes`` were written at ``now``."""
        self.last_tx_s = now
        self.free_at = max(now, self.free_at) + n_bytes * self.byte_s

    def reply_in(self, now: float) -> None:
        """Every reply asked for is in: the wire is quiet (an emulator without wire
        timing answers faster than the wire, so the estimate must not run ahead)."""
        self.free_at = min(self.free_at, now)

    def failed(self, now: float) -> None:
        """A reply failed at ``now``: a late one may still be on its way."""
        self.failed_at = now

    def request_start(self, now: float, held_bytes: int, last_rx_s: float) -> float:
        """When a request written now would start on the wire: after what is still on
        it, ``held_bytes`` sent ahead of it, and the quiet time after a failed reply
        (``last_rx_s``: when bytes last came in)."""
        start = max(now, self.free_at) + held_bytes * self.byte_s
        if self.failed_at is None:
            return start
        return max(start, self._quiet_from(last_rx_s))

    def quiet_wait_s(self, now: float, last_rx_s: float) -> float:
        """How much later than the wire alone allows a request must start for the quiet
        a failed reply asks (0 when no reply failed since the last request)."""
        if self.failed_at is None:
            return 0.0
        return max(0.0, self._quiet_from(last_rx_s) - max(now, self.free_at))

    def _quiet_from(self, last_rx_s: float) -> float:
        """When the line has been quiet long enough after the failed reply."""
        assert self.failed_at is not None
        return max(self.failed_at, last_rx_s) + self.reply_gap_s

    def fits(self, start_s: float, n_bytes: int, deadline_s: float) -> bool:
        """Whether ``n_bytes`` starting at ``start_s`` are off the wire by ``deadline_s``."""
        return start_s + n_bytes * self.byte_s <= deadline_s

    def reply_deadline(self, now: float) -> float:
        """When a reply to a request sent now is overdue (the wire may still be busy)."""
        return max(now, self.free_at) + self.reply_timeout_s

    def take_quiet_wait(self, now: float, deadline_s: float | None) -> tuple[float, float] | None:
        """Before a request: (since, at most) to wait for a quiet line after a failed
        reply (then cleared), or None when no reply failed since the last request."""
        if self.failed_at is None:
            return None
        since, self.failed_at = self.failed_at, None
        most = self.reply_timeout_s
        if deadline_s is not None:
            most = min(most, deadline_s - now)
        return since, max(0.0, most)
