"""One servo bus shared by two loops: each hand of a two-hand rig on one wire.

:class:`SharedBus` holds the bus (any :class:`~handrig.devices.servo.bus.ServoBus`)
and a lock; :meth:`SharedBus.part` gives each loop a :class:`BusPart`, itself a
``ServoBus`` over its own servos (rig indices ``indices`` of the whole bus), so a
loop sees only its hand. On the wire there is one writer at a time: a part's
write takes the lock, puts its goals into the whole bus's goal vector (the other
part's are its last ones, already clamped) and sends one Sync Write to every
servo. Only the first part (the reader) reads the servos back, every servo in one
read; another part's read hands it its servos of the newest read it has not seen
(its silence watch and tracking see every read once), and declines (``sent=False``)
when there is none: reads by both loops would take twice the wire and make each
hand's writes wait behind the other's reads. A part's write waits at most for the
other part's write or the reader's read in progress (at 4 Mbps, 40 servos: about
0.5 ms for a write).

Torque, connect and close belong to whoever opened the bus (the session): a part's
:meth:`BusPart.torque` does nothing, and the part's loop runs inside the whole
bus's torque context.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator, Sequence
from contextlib import AbstractContextManager

import numpy as np

from handrig.clock import Clock
from handrig.devices.servo.bus import BusStats, ServoBus, ServoState

READ_HOLD_WIRES = 2.0
READ_HOLD_EXTRA_S = 0.0003
"""A read holds the shared wire at most this many times its wire time plus this long:
a late reply is left stale (the silence tiers see it) rather than hold the other
hand's next write back until the reader's own next frame."""


class SharedBus:
    """``bus`` (connected by its owner) shared by the loops of :meth:`part`; ``clock``
    the bus's (the reads' deadlines are on it)."""

    def __init__(self, bus: ServoBus, clock: Clock) -> None:
        self.bus = bus
        self.clock = clock
        self.lock = threading.Lock()
        self._goals = np.full(bus.n_servos, np.nan)
        self._rehearsal_goals = np.full(bus.n_servos, np.nan)  # :meth:`rehearse`'s own
        self._events_to: BusPart | None = None  # the part the bus's own events go to
        self.reader: BusPart | None = None  # the part whose loop reads the servos back
        self.latest: ServoState | None = None  # the reader's newest read
        self.reads = 0  # reads the reader made

    def part(self, indices: Sequence[int]) -> BusPart:
        """The servos at rig indices ``indices`` (of the whole bus) as a bus of their
        own. The first part made gets the bus's events (:meth:`ServoBus.drain_events`)."""
        p = BusPart(self, indices)
        if self._events_to is None:
            self._events_to = p
        if self.reader is None:
            self.reader = p
        return p

    def write(self, index: np.ndarray, goals_deg: np.ndarray) -> tuple[int, float]:
        """Goals for the servos at ``index``, the other servos' last goals, one write;
        returns the clamp count and when the write was handed to the OS."""
        with self.lock:
            bus = self.bus
            goals = self._goals
            last = bus.last_goals_deg
            goals[:] = last
            goals[index] = goals_deg
            # a servo never written yet holds where torque-on left it: NaN goals are the
            # bus's to replace (it holds the servo and counts a clamp); not this part's
            missing = ~np.isfinite(goals)
            missing[index] = False
            clamps = bus.write_goals_deg(goals)
            if missing.any():
                clamps -= int(np.count_nonzero(missing))
            return max(clamps, 0), bus.last_write_s

    def rehearse(self, index: np.ndarray, goals_deg: np.ndarray) -> None:
        """:meth:`write`'s goal vector put together in scratch and the bus's goal write
        rehearsed (:meth:`ServoBus.rehearse_write`); without the lock: it reads the goals
        last sent and writes only scratch, so a loop's warm-up never waits for the other's
        write."""
        goals = self._rehearsal_goals
        goals[:] = self.bus.last_goals_deg
        goals[index] = goals_deg
        self.bus.rehearse_write(goals)

    def read(self, deadline_s: float | None, part: tuple[int, int] | None) -> ServoState:
        n = self.bus.n_servos if part is None else -(-self.bus.n_servos // part[1])
        cap = self.clock.now() + READ_HOLD_WIRES * self.bus.read_wire_s(n) + READ_HOLD_EXTRA_S
        deadline_s = cap if deadline_s is None else min(deadline_s, cap)
        with self.lock:
            state = self.bus.read_state(deadline_s, part)
            if state.sent:
                self.latest = state
                self.reads += 1
            return state

    def housekeeping(self, deadline_s: float) -> bool:
        """The bus's upkeep, in a gap the other loop is not using, and holding the wire
        no longer than a read of every servo may (:data:`READ_HOLD_WIRES`)."""
        if not self.lock.acquire(blocking=False):
            return False  # the other loop has the wire: upkeep waits for a free gap
        try:
            cap = (self.clock.now() + READ_HOLD_WIRES * self.bus.read_wire_s(self.bus.n_servos)
                   + READ_HOLD_EXTRA_S)
            return self.bus.housekeeping(min(deadline_s, cap))
        finally:
            self.lock.release()


class BusPart(ServoBus):
    """Some servos of a :class:`SharedBus`, in their rig order, as a bus of their own."""

    def __init__(self, shared: SharedBus, indices: Sequence[int]) -> None:
        bus = shared.bus
        self.shared = shared
        self.index = np.asarray(indices, dtype=np.intp)
        if not len(self.index) or len(set(self.index.tolist())) != len(self.index):
            raise ValueError(f"a bus part needs distinct servo indices, got {indices}")
        self._ids = tuple(bus.ids[i] for i in self.index)
        self._joints = tuple(bus.joint_names[i] for i in self.index)
        self._of_whole = {int(w): k for k, w in enumerate(self.index)}
        self.port, self.baud, self.emulated = bus.port, bus.baud, bus.emulated
        self._last_write_s = float("nan")
        self._seen = 0  # the reader's reads this part has had

    # -- the contract ---------------------------------------------------------------------
    @property
    def joint_names(self) -> tuple[str, ...]:
        return self._joints

    @property
    def ids(self) -> tuple[int, ...]:
        return self._ids

    @property
    def stats(self) -> BusStats:
        """The whole bus's counters (one wire, one ledger)."""
        return self.shared.bus.stats

    def connect(self) -> None:
        """Nothing: the shared bus's owner connects it."""

    def close(self) -> None:
        """Nothing: the shared bus's owner closes it (torque off on the way)."""

    def torque(self, *, handle_signals: bool = True) -> AbstractContextManager[ServoBus]:
        """Nothing to switch: the part's loop runs inside the whole bus's torque context,
        which turns torque off for every servo on every way out."""
        return self._held()

    @contextlib.contextmanager
    def _held(self) -> Iterator[ServoBus]:
        yield self

    def write_goals_deg(self, goals_deg: np.ndarray) -> int:
        clamps, when = self.shared.write(self.index, goals_deg)
        self._last_write_s = when
        return clamps

    def rehearse_write(self, goals_deg: np.ndarray) -> None:
        self.shared.rehearse(self.index, goals_deg)

    def read_state(self, deadline_s: float | None = None,
                   part: tuple[int, int] | None = None, *, patient: bool = False
                   ) -> ServoState:
        shared = self.shared
        if shared.reader is not self:
            return self._newest_read()
        st = shared.read(deadline_s, part)  # the reader asks the whole bus's servos
        return self._own(st)

    def _newest_read(self) -> ServoState:
        """The reader's newest read if this part has not had it, else a declined read
        (every servo stale with its last reading)."""
        latest, reads = self.shared.latest, self.shared.reads
        if latest is not None and reads != self._seen:
            self._seen = reads
            return self._own(latest)
        if latest is None:  # nothing read yet
            n = len(self.index)
            nan = np.full(n, np.nan)
            return ServoState(nan, nan.copy(), nan.copy(), nan.copy(), np.zeros(n, np.uint8),
                              np.zeros(n, np.uint8), np.ones(n, bool), np.full(n, np.inf),
                              float("nan"), self._stats_of(self.shared.bus.stats.copy()),
                              None, False)
        st = self._own(latest)
        st.stale = np.ones(len(self.index), bool)
        st.sent = False
        return st

    def _stats_of(self, stats: BusStats) -> BusStats:
        ix = self.index
        stats.n_servos = len(ix)
        stats.stale_readings = stats.stale_readings[ix]
        stats.hardware_errors = stats.hardware_errors[ix]
        stats.reboots = stats.reboots[ix]
        return stats

    def _own(self, st: ServoState) -> ServoState:
        """This part's servos of a read of the whole bus."""
        ix = self.index
        asked = None if st.asked is None else st.asked[ix]
        stats = self._stats_of(st.stats.copy())  # this part's servos' counters
        return ServoState(
            st.positions_deg[ix], st.velocities_dps[ix], st.currents_ma[ix],
            st.temperatures_c[ix], st.status_errors[ix], st.hardware_errors[ix],
            st.stale[ix], st.age_s[ix], st.timestamp_s, stats, asked, st.sent,
            None if st.stopped is None else st.stopped[ix])

    # -- hooks ------------------------------------------------------------------------------
    @property
    def last_goals_deg(self) -> np.ndarray:
        return np.asarray(self.shared.bus.last_goals_deg)[self.index]

    @property
    def left_out(self) -> tuple[int, ...]:
        return tuple(self._of_whole[i] for i in self.shared.bus.left_out
                     if i in self._of_whole)

    @property
    def last_write_s(self) -> float:
        return self._last_write_s

    def read_wire_s(self, n: int) -> float:
        """The reader asks the whole bus's servos: ``n`` of this part's, as many of the
        other's; another part's read takes no wire."""
        if self.shared.reader is not self:
            return 0.0
        whole = self.shared.bus.n_servos
        return self.shared.bus.read_wire_s(min(whole, -(-n * whole // len(self.index))))

    def write_wire_s(self) -> float:
        """A write carries every servo of the bus (the other part's last goals too)."""
        return self.shared.bus.write_wire_s()

    def quiet_wait_s(self) -> float:
        return self.shared.bus.quiet_wait_s()

    def housekeeping(self, deadline_s: float) -> bool:
        """The reader's loop does the bus's upkeep; another part has none."""
        if self.shared.reader is not self:
            return False
        return self.shared.housekeeping(deadline_s)

    def drain_events(self) -> list[str]:
        if self.shared._events_to is not self:
            return []
        with self.shared.lock:
            return self.shared.bus.drain_events()

    def describe(self, index: int) -> str:
        return self.shared.bus.describe(int(self.index[index]))
