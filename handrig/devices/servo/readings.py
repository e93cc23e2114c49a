"""The latest readings of every servo and the states a read returns.

``latest`` rows (rig order): position deg, velocity deg/s, current mA,
temperature deg C, clock time read; the codec kernels write into them in place.
A state handed to a caller holds copies: scribbling on it changes nothing here.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Literal

import numpy as np

from handrig.devices.servo.bus import BusStats, ServoState
from handrig.devices.servo.registers import Reg

log = logging.getLogger("handrig.devices.servo")

ReadFields = Literal["position", "motion"]
# Contiguous control-table spans read each cycle: position only, or current+velocity+position.
READ_SPANS: dict[str, tuple[int, int]] = {
    "position": (Reg.PRESENT_POSITION.address, 4),
    "motion": (Reg.PRESENT_CURRENT.address, 10),
}


class ReadPlan:
    """What each present-state read fetches and by which instruction.

    ``fast``: Fast Sync Read (one reply for every servo); False after a fallback to
    plain Sync Read, which is for good. ``notes`` gets a line when that happens.
    """

    def __init__(self, fields: ReadFields, stats: BusStats, where: str, notes: list[str]) -> None:
        if fields not in READ_SPANS:
            raise ValueError(f"read_fields must be one of {sorted(READ_SPANS)}")
        self.fields: ReadFields = fields
        self.address, self.data_len = READ_SPANS[fields]
        self.fast = True
        self._stats = stats
        self._where = where
        self._notes = notes

    def fall_back(self, why: str) -> None:
        """From Fast Sync Read to Sync Read, counted and said once."""
        if self.fast:
            self.fast = False
            self._stats.fallbacks += 1
            msg = f"falling back from Fast Sync Read to Sync Read {self._where}: {why}"
            self._notes.append(msg)
            log.warning(msg)


class Readings:
    """The latest reading of each of ``n`` servos, what the current read got, and the
    states made from them."""

    def __init__(self, n: int, stats: BusStats,
                 totals: Callable[[], BusStats] | None = None) -> None:
        self.n = n
        self.stats = stats  # this part's own counters (stale readings)
        # the bus's counters, summed over its parts, that each state carries
        self._totals: Callable[[], BusStats] = totals or stats.copy
        self.latest = np.full((5, n), np.nan)
        self.positions_deg, self.velocities_dps, self.currents_ma = self.latest[:3]
        self.temperatures_c, self.read_time = self.latest[3], self.latest[4]
        self.read_time[:] = -np.inf
        self.status_err = np.zeros(n, np.uint8)  # ERR bytes of this read
        self.hw_err = np.zeros(n, np.uint8)  # Hardware Error Status found in this read
        self.fresh = np.zeros(n, bool)  # valid readings in this read
        self.stale_run = np.zeros(n, np.int64)  # reads in a row without a valid reading
        self._next: tuple[ServoState, np.ndarray, np.ndarray] | None = None

    def start_read(self) -> None:
        """A new read: nothing fresh, no errors yet."""
        self.fresh[:] = False
        self.status_err[:] = 0
        self.hw_err[:] = 0

    def note_hardware_error(self, index: int, bits: int) -> None:
        """Servo ``index`` reported Hardware Error Status ``bits`` in this read (its bits
        are the bus contract's :class:`~handrig.devices.servo.bus.ServoFault` as they are)."""
        self.hw_err[index] = bits

    def mark(self, now: float, asked: np.ndarray | None = None) -> np.ndarray:
        """The read is over at ``now``: stale runs and times updated; returns ``stale``.
        ``asked``: the indices a read of a part asked for (the others are left as they
        were, and are not stale for this read)."""
        fresh = self.fresh
        if asked is not None:
            got = fresh[asked]
            missing, answered = asked[~got], asked[got]
            self.stale_run[missing] += 1
            self.stale_run[answered] = 0
            self.stats.stale_readings[missing] += 1
            self.read_time[answered] = now
            stale = np.zeros(self.n, bool)
            stale[missing] = True
            return stale
        stale = ~fresh
        if fresh.all():
            self.stale_run[:] = 0
            self.read_time[:] = now
        else:
            self.stale_run[stale] += 1
            self.stale_run[fresh] = 0
            self.stats.stale_readings[stale] += 1
            self.read_time[fresh] = now
        return stale

    def snapshot(self, now: float, stale: np.ndarray, hardware_errors: np.ndarray,
                 asked: np.ndarray | None = None,
                 stopped: np.ndarray | None = None) -> ServoState:
        """A state of copies of the latest readings and counters, marked ``stale``
        (``asked``: the indices a read of a part asked for; ``stopped``: see
        :attr:`ServoState.stopped`)."""
        mask = None
        if asked is not None:
            mask = np.zeros(self.n, bool)
            mask[asked] = True
        return ServoState(
            positions_deg=self.positions_deg.copy(),
            velocities_dps=self.velocities_dps.copy(),
            currents_ma=self.currents_ma.copy(),
            temperatures_c=self.temperatures_c.copy(),
            status_errors=self.status_err.copy(),
            hardware_errors=hardware_errors,
            stale=stale,
            age_s=now - self.read_time,
            timestamp_s=now,
            stats=self._totals(),
            asked=mask,
            stopped=stopped,
        )

    def unread(self, now: float) -> ServoState:
        """The state of a read that was not sent: every servo stale, its last reading."""
        state = self.snapshot(now, np.ones(self.n, bool), np.zeros(self.n, np.uint8))
        state.sent = False
        return state

    def prepare_whole(self) -> tuple[np.ndarray, np.ndarray]:
        """Allocate the state a whole read returns (arrays and counters as they will be
        if the read is whole), while the request and reply are on the wire; returns
        the arrays the whole-reply kernel fills."""
        n = self.n
        out = np.empty((5, n))
        out_u8 = np.empty((3, n), np.uint8)
        state = ServoState(
            positions_deg=out[0], velocities_dps=out[1], currents_ma=out[2],
            temperatures_c=out[3], status_errors=out_u8[0], hardware_errors=out_u8[1],
            stale=out_u8[2].view(np.bool_), age_s=out[4], timestamp_s=np.nan,
            stats=self._totals(),
        )
        self._next = (state, out, out_u8)
        return out, out_u8

    def recount_whole(self) -> None:
        """Counters changed after :meth:`prepare_whole` (a late reply was dropped)."""
        if self._next is not None:
            self._next[0].stats = self._totals()

    def take_whole(self, timestamp_s: float) -> ServoState:
        """The state :meth:`prepare_whole` allocated, now filled by the kernel."""
        assert self._next is not None, "take_whole without prepare_whole"
        state = self._next[0]
        self._next = None
        state.timestamp_s = timestamp_s
        return state
