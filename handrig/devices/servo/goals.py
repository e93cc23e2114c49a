"""The goal writer: goals clamped, built into the compiled goal Sync Write, and sent.

The Sync Write of Goal Position is preallocated once and rebuilt in place each
cycle by :func:`handrig.devices.servo.codec.goal_packet` (clamp, ticks and CRC in one
compiled loop), then written to the port in one write. Ticks in 0..4095 and IDs
<= 252 never form ``FF FF FD``: the packet needs no stuffing.
"""

from __future__ import annotations

import numpy as np

from handrig.devices.servo import codec
from handrig.devices.servo.bus import BusStats
from handrig.devices.servo.link import Link
from handrig.devices.servo.registers import Reg
from handrig.devices.servo.roster import Roster


class GoalWriter:
    """Goal Sync Writes for the servos of ``roster`` through ``link``."""

    def __init__(self, roster: Roster, link: Link, stats: BusStats) -> None:
        self.roster = roster
        self.link = link
        self.stats = stats
        n = roster.n
        self._goal_deg = np.zeros(n, np.float64)
        self.last_goal_deg = np.full(n, np.nan)
        """The goals last sent, after clamping (NaN before the first write; NaN for a
        servo left out)."""
        self.left_out = np.zeros(n, bool)
        self._build_packet()
        # what :meth:`rehearse` builds into: never sent
        self._scratch_goal = np.zeros(n, np.float64)
        self._scratch_packet = self.packet.copy()

    def leave_out(self, indices: np.ndarray) -> None:
        """Never send servos ``indices`` a goal (absent at start-up, not commissioned):
        the Sync Write carries the others only."""
        self.left_out[np.asarray(indices, np.intp)] = True
        self._build_packet()

    def admit(self, index: int, goal_deg: float) -> None:
        """Send servo ``index`` goals from now on, starting from ``goal_deg`` (where it
        was given torque, within its limits): the Sync Write carries it again."""
        self.left_out[index] = False
        self._build_packet()
        self._goal_deg[index] = goal_deg
        self.last_goal_deg[index] = goal_deg

    def _build_packet(self) -> None:
        r = self.roster
        keep = np.flatnonzero(~self.left_out)
        self._keep = keep if keep.size < r.n else None
        m = int(keep.size)
        prefix = codec.sync_write_prefix(Reg.GOAL_POSITION.address, 4, m)
        self.packet = np.zeros(codec.SYNC_WRITE_BODY + 5 * m + 2, np.uint8)
        self.packet[: len(prefix)] = np.frombuffer(prefix, np.uint8)
        self.packet[codec.SYNC_WRITE_BODY :: 5][:m] = np.asarray(r.ids, np.uint8)[keep]
        self._view = self.packet.data  # a memoryview: what is written to the port
        # the kernel's rows for the servos kept (when some are left out)
        self._rows = tuple(np.ascontiguousarray(a[keep]) for a in (
            r.min_deg, r.max_deg, r.hold_deg, r.ticks_per_deg, r.zero_ticks))
        self._sub_goal = np.zeros(m, np.float64)
        self._sub_in = np.zeros(m, np.float64)
        self._sub_last = np.zeros(m, np.float64)
        self._goal_deg[self.left_out] = np.nan
        self.last_goal_deg[self.left_out] = np.nan

    def build(self, goals_deg: np.ndarray) -> int:
        """Clamp ``goals_deg`` and build the goal Sync Write; returns (and counts) how
        many goals changed. Nothing is sent."""
        clamped = self._clamp_into(goals_deg, self._goal_deg, self.packet)
        self.stats.clamps += clamped
        return clamped

    def rehearse(self, goals_deg: np.ndarray) -> None:
        """Build ``goals_deg`` into a scratch packet with the same compiled loop as
        :meth:`build` (the loop's warm-up): nothing is sent or counted, and the goals
        last sent stay as they are. With servos left out, nothing (the packet then has
        another shape: the first real build warms it)."""
        r = self.roster
        if self._keep is not None or goals_deg.shape != (r.n,):
            return
        codec.goal_packet(np.ascontiguousarray(goals_deg, dtype=np.float64), r.min_deg,
                          r.max_deg, self.last_goal_deg, r.hold_deg, r.ticks_per_deg,
                          r.zero_ticks, self._scratch_goal, self._scratch_packet)

    def send_built(self) -> None:
        """Send the Sync Write :meth:`build` built."""
        self.link.send(self._view, answered=False)
        self.stats.writes += 1
        self.last_goal_deg[:] = self._goal_deg

    def hold_built(self) -> None:
        """Hand the built Sync Write to the link, to go out with the next request."""
        self.link.hold(self.packet.tobytes())
        self.last_goal_deg[:] = self._goal_deg
        self.stats.writes += 1

    def send_held(self) -> None:
        """Send a held Sync Write that no request took along."""
        if self.link.holding:
            self.link.send(b"", answered=False)

    def remember(self, goal_deg: np.ndarray) -> None:
        """Take ``goal_deg`` as the goals last sent (a torque-on that wrote them servo by
        servo): a reboot then re-sends them."""
        self.last_goal_deg[:] = goal_deg
        self.last_goal_deg[self.left_out] = np.nan

    def resend(self, goal_deg: np.ndarray) -> None:
        """Send ``goal_deg`` (already within limits) as the goal Sync Write, uncounted
        as a clamp (keeps the Bus Watchdogs fed while a servo restarts)."""
        self._clamp_into(goal_deg, self._goal_deg, self.packet)
        self.send_built()

    def _clamp_into(self, goals_deg: np.ndarray, goal: np.ndarray, packet: np.ndarray) -> int:
        r = self.roster
        g = np.ascontiguousarray(goals_deg, dtype=np.float64)
        if g.shape != (r.n,):
            raise ValueError(f"goals_deg must have shape ({r.n},), got {g.shape}")
        keep = self._keep
        if keep is None:
            return int(codec.goal_packet(
                g, r.min_deg, r.max_deg, self.last_goal_deg, r.hold_deg, r.ticks_per_deg,
                r.zero_ticks, goal, packet))
        low, high, hold, tpd, zero = self._rows
        np.take(g, keep, out=self._sub_in)
        np.take(self.last_goal_deg, keep, out=self._sub_last)
        changed = int(codec.goal_packet(self._sub_in, low, high, self._sub_last, hold, tpd,
                                        zero, self._sub_goal, packet))
        goal[keep] = self._sub_goal  # the servos left out keep NaN: never sent
        return changed
