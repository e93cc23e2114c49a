"""Instruction semantics of the emulated bus: which servo hears a packet, what it answers.

:class:`Dispatcher` is mixed into :class:`sim.dxl_bus.SimBus`, which owns the line
and the timing; this part turns one parsed instruction into the status packets
the servos send (unicast, broadcast, sync/bulk and fast reads), with faults applied.

Baud: a servo hears only packets sent at its own Baud Rate item (a real servo at
another rate decodes noise and stays silent), unless ``check_baud`` is off.

Goal audit: every Goal Position the bus decodes (Sync Write or Write) is
counted in ``stats.goals_decoded``; with ``goal_limits`` (from the rig: each
calibrated servo's ``[min_deg, max_deg]`` in ticks) one outside them is counted
in ``stats.goals_outside``, the driver-side promise checked from the servo side.
"""

from __future__ import annotations

import random
import threading
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple, overload

from firmware_protocol.dynamixel import (
    BAUD_BY_INDEX,
    BROADCAST_ID,
    INDEX_BY_BAUD,
    MAX_PACKET_LEN,
    ErrorCode,
    Instruction,
    PacketError,
    build_fast_read_reply,
    build_status,
    split_bulk_read,
    split_bulk_write,
    split_sync_read,
    split_sync_write,
)
from handrig.clock import Clock
from sim.dxl_fast import (
    COMPILED,
    PACKET_PATH,
    ReadPlan,
    WritePlan,
    answer_read,
    goals_heard,
    mark_heard,
    read_plan,
    write_goals,
    write_plan,
)
from sim.dxl_faults import FaultSpec, apply_faults
from sim.dxl_rig import GOAL_POSITION_ADDRESS
from sim.dxl_servo import READABLE_BYTES, EmulatedServo

# Per-packet host overhead is binned by the microsecond up to this many; longer ones
# go to the last bin (enough for p50/p99 without keeping every sample).
OVERHEAD_BINS_US = 5000


def _overhead_bins() -> list[int]:
    return [0] * (OVERHEAD_BINS_US + 1)


@dataclass
class BusStats:
    """Counters and host-overhead figures of the emulated bus."""

    packets: int = 0
    replies: int = 0
    bad_crc: int = 0
    noise_bytes: int = 0
    overhead_total_s: float = 0.0
    overhead_max_s: float = 0.0
    late_total_s: float = 0.0
    late_max_s: float = 0.0
    by_instruction: Counter[int] = field(default_factory=Counter)
    goals_decoded: int = 0  # Goal Position values received
    goals_outside: int = 0  # of those, outside the servo's goal_limits
    overhead_bins: list[int] = field(default_factory=_overhead_bins)
    """Packets by host overhead, whole microseconds (the last bin: that long or more)."""

    def note_overhead(self, overhead_s: float) -> None:
        """Count one packet's host time from its last byte read to its reply ready."""
        self.overhead_total_s += overhead_s
        if overhead_s > self.overhead_max_s:
            self.overhead_max_s = overhead_s
        us = int(overhead_s * 1e6)
        self.overhead_bins[us if 0 <= us < OVERHEAD_BINS_US else OVERHEAD_BINS_US] += 1

    def overhead_quantile_s(self, q: float) -> float:
        """The ``q`` quantile (0..1) of the per-packet host overhead, to the microsecond
        above (0 before any packet)."""
        total = sum(self.overhead_bins)
        if not total:
            return 0.0
        rank = q * total
        seen = 0
        for us, count in enumerate(self.overhead_bins):
            seen += count
            if seen >= rank and count:
                return (us + 1) * 1e-6
        return (OVERHEAD_BINS_US + 1) * 1e-6

    def overhead_line(self) -> str:
        """The overhead figures as the closing lines print them, with which packet path
        answered (compiled, or pure Python where sim/_dxl_c.c was not built)."""
        return (f"host overhead per packet p50 {self.overhead_quantile_s(0.5) * 1e6:.0f} us, "
                f"p99 {self.overhead_quantile_s(0.99) * 1e6:.0f} us, "
                f"mean {self.overhead_mean_s * 1e6:.0f} us, max {self.overhead_max_s * 1e6:.0f} us "
                f"({PACKET_PATH} packet path)")

    @property
    def overhead_mean_s(self) -> float:
        """Mean host time from a packet's last byte read to its reply ready to send."""
        return self.overhead_total_s / self.packets if self.packets else 0.0

    @property
    def late_mean_s(self) -> float:
        """Mean time a reply left after its wire-time instant (wire timing on)."""
        return self.late_total_s / self.replies if self.replies else 0.0


class _Reply(NamedTuple):
    """Bytes a servo sends, after its Return Delay Time (and a fault's extra delay)."""

    data: bytes
    return_delay_s: float
    fault_delay_s: float = 0.0


class SyncReads(Sequence[tuple[int, int, int]]):
    """The ``(id, address, length)`` requests of a Fast Sync Read, from its parameters
    (checked: :class:`PacketError` when too short), listed only when asked for."""

    def __init__(self, params: bytes) -> None:
        self.address, self.length, self.ids = split_sync_read(params)
        self.params = params
        self._items: list[tuple[int, int, int]] | None = None

    def __len__(self) -> int:
        return len(self.ids)

    @overload
    def __getitem__(self, k: int) -> tuple[int, int, int]: ...

    @overload
    def __getitem__(self, k: slice) -> list[tuple[int, int, int]]: ...

    def __getitem__(self, k: int | slice) -> tuple[int, int, int] | list[tuple[int, int, int]]:
        if self._items is None:
            self._items = [(i, self.address, self.length) for i in self.ids]
        return self._items[k]


class Dispatcher:
    """The servos behind the line and what they answer (state owned by the bus)."""

    servos: list[EmulatedServo]
    stats: BusStats
    fault_counts: Counter[str]
    goal_limits: dict[int, tuple[int, int]]
    on_sync_write: Callable[[float, int, list[tuple[int, bytes]]], None] | None
    check_baud: bool
    lock: threading.RLock
    _faults: FaultSpec
    _rng: random.Random
    _by_id: dict[int, EmulatedServo]
    _on_bus: tuple[EmulatedServo, ...]  # _by_id's servos, and their control tables
    _on_bus_mems: tuple[bytearray, ...]
    _packet_baud: int
    _generation: int
    _read_plans: dict[bytes, ReadPlan]
    _write_plans: dict[bytes, WritePlan]
    _overload_done: bool
    _started_at: float
    clock: Clock
    compiled: bool = COMPILED
    """The hot packets through sim/_dxl_c.c (where built); False: the same bytes from
    pure Python (:mod:`sim.dxl_fast`)."""

    @property
    def faults(self) -> FaultSpec:
        """The fault switches; assigning new ones (at any time) reseeds their random
        source and applies ``missing`` at once (``overload`` only counts from start)."""
        return self._faults

    @faults.setter
    def faults(self, spec: FaultSpec) -> None:
        with self.lock:
            self._faults = spec
            self._rng = random.Random(spec.seed)
            self._overload_done = False
            self._rebuild_ids()

    def servo(self, servo_id: int) -> EmulatedServo:
        """The emulated servo with this ID (missing ones included)."""
        for s in self.servos:
            if s.id == servo_id:
                return s
        raise KeyError(f"no emulated servo with ID {servo_id}")

    def _rebuild_ids(self) -> None:
        self._by_id = {s.id: s for s in self.servos if s.id not in self.faults.missing}
        self._on_bus = tuple(self._by_id.values())
        self._on_bus_mems = tuple(s.mem for s in self._on_bus)
        # the quick paths' plans (sim.dxl_fast) name servos by ID: made again on next use
        self._generation += 1
        self._read_plans = {}
        self._write_plans = {}

    def _baud_index(self) -> int:
        """The Baud Rate item a servo needs to hear this packet; -1: every servo hears
        it; -2: none does (not an X-series rate)."""
        if not self.check_baud or not self._packet_baud:
            return -1
        return INDEX_BY_BAUD.get(self._packet_baud, -2)

    # ------------------------------------------------------------ dispatch

    def _muted(self, servo_id: int, now: float) -> bool:
        """The ``mute`` fault: this servo sends no status now."""
        f = self._faults
        if servo_id not in f.mute:
            return False
        since = now - self._started_at
        if f.mute_from_s <= since < f.mute_until_s:
            self.fault_counts["muted replies"] += 1
            return True
        return False

    def _reply(self, servo: EmulatedServo, error: int, data: bytes = b"",
               from_id: int | None = None) -> _Reply:
        """One status packet, with faults applied; from the servo's ID, or ``from_id``:
        the ID a packet that changed it (ID write, Factory Reset) addressed."""
        if self._faults.mute and self._muted(servo.id, self.clock.now()):
            return _Reply(b"", servo.return_delay_s)
        packet = build_status(servo.id if from_id is None else from_id, error, data)
        extra = 0.0
        if self.faults.any_reply_fault:
            packet, extra = self._apply_faults(
                packet, servo.id, lambda other: build_status(other, error, data))
        return _Reply(packet, servo.return_delay_s, extra)

    def _apply_faults(
        self, packet: bytes, servo_id: int, rebuild: Callable[[int], bytes]
    ) -> tuple[bytes, float]:
        """Drop, misaddress (``rebuild(other_id)``), corrupt, truncate or delay a reply."""
        return apply_faults(self.faults, self._rng, self.fault_counts, packet, servo_id, rebuild)

    def _servo_for(self, servo_id: int, now: float) -> EmulatedServo | None:
        servo = self._by_id.get(servo_id)
        if servo is None:
            if servo_id in self.faults.missing:
                self.fault_counts["missing"] += 1
            return None
        if not servo.available(now) or not self._hears(servo):
            return None
        servo.last_heard = now
        return servo

    def _hears(self, servo: EmulatedServo) -> bool:
        """With ``check_baud``, a servo hears only packets at its Baud Rate item
        (``_packet_baud`` 0: bytes fed without a line, heard by all)."""
        return (not self.check_baud or not self._packet_baud
                or BAUD_BY_INDEX.get(servo.mem[8]) == self._packet_baud)

    def _listening(self, now: float) -> list[EmulatedServo]:
        """Servos that hear a broadcast now, in ID order."""
        return sorted((s for s in self._by_id.values() if s.available(now) and self._hears(s)),
                      key=lambda s: s.id)

    def _dispatch(
        self, target: int, inst: int, params: bytes, now: float
    ) -> list[_Reply]:
        if target == BROADCAST_ID:
            mark_heard(self._on_bus, self._on_bus_mems, now, self._baud_index(),
                       self.compiled)
            return self._broadcast(inst, params, now)
        servo = self._servo_for(target, now)
        if servo is None:
            return []
        level = servo.status_return_level
        try:
            if inst == Instruction.PING:
                return [self._reply(servo, *servo.ping())]
            if inst == Instruction.READ:
                if len(params) != 4:
                    return self._error(servo, ErrorCode.DATA_LENGTH, level >= 1)
                address = params[0] | params[1] << 8
                length = params[2] | params[3] << 8
                err, data = servo.read(address, length)
                return [self._reply(servo, err, data)] if level >= 1 else []
            if inst in (Instruction.WRITE, Instruction.REG_WRITE):
                if len(params) < 3:
                    return self._error(servo, ErrorCode.DATA_LENGTH, level >= 2)
                address = params[0] | params[1] << 8
                if address == GOAL_POSITION_ADDRESS and len(params) == 6:
                    self._audit_goal(servo.id, params[2:])
                if inst == Instruction.WRITE:
                    err = servo.write(address, params[2:])
                else:
                    err = servo.reg_write(address, params[2:])
                if address <= 7 < address + len(params) - 2:
                    self._rebuild_ids()
                # a servo answers from the ID it was addressed by, then takes a new one
                return [self._reply(servo, err, from_id=target)] if level >= 2 else []
            if inst == Instruction.ACTION:
                err = servo.action()
                self._rebuild_ids()
                return [self._reply(servo, err, from_id=target)] if level >= 2 else []
            if inst == Instruction.REBOOT:
                err = servo.reboot(now)
                return [self._reply(servo, err)] if level >= 2 else []
            if inst == Instruction.FACTORY_RESET:
                option = params[0] if len(params) == 1 else 0
                err = servo.factory_reset(option, now)
                reply = [self._reply(servo, err, from_id=target)] if level >= 2 else []
                self._rebuild_ids()
                return reply
            if inst == Instruction.CLEAR:
                return [self._reply(servo, servo.error_byte())] if level >= 2 else []
            # Sync/bulk instructions are broadcast only; anything else is unknown.
            return self._error(servo, ErrorCode.INSTRUCTION, True)
        except PacketError:
            return self._error(servo, ErrorCode.DATA_LENGTH, True)

    def _audit_goal(self, servo_id: int, data: bytes) -> None:
        self.stats.goals_decoded += 1
        limits = self.goal_limits.get(servo_id)
        if limits is not None:
            goal = int.from_bytes(data, "little", signed=True)
            if not limits[0] <= goal <= limits[1]:
                self.stats.goals_outside += 1

    def _error(self, servo: EmulatedServo, code: int, reply: bool) -> list[_Reply]:
        return [self._reply(servo, servo.error_byte(code))] if reply else []

    def _broadcast(self, inst: int, params: bytes, now: float) -> list[_Reply]:
        try:
            if inst == Instruction.SYNC_WRITE:
                if self._quick_goal_write(params, now):
                    return []
                address, length, items = split_sync_write(params)
                if address == GOAL_POSITION_ADDRESS and length == 4:
                    for servo_id, data in items:
                        self._audit_goal(servo_id, data)
                if self.on_sync_write is not None:
                    self.on_sync_write(now, address, list(items))
                for servo_id, data in items:
                    servo = self._servo_for(servo_id, now)
                    if servo is not None:
                        servo.write(address, data)
                if address <= 7 < address + length:
                    self._rebuild_ids()
                return []
            if inst == Instruction.FAST_SYNC_READ:
                return self._fast_read(SyncReads(params), now)
            if inst == Instruction.SYNC_READ:
                address, length, ids = split_sync_read(params)
                out: list[_Reply] = []
                for servo_id in ids:
                    servo = self._servo_for(servo_id, now)
                    if servo is not None and servo.status_return_level >= 1:
                        out.append(self._reply(servo, *servo.read(address, length)))
                return out
            if inst == Instruction.BULK_READ:
                out = []
                for servo_id, address, length in split_bulk_read(params):
                    servo = self._servo_for(servo_id, now)
                    if servo is not None and servo.status_return_level >= 1:
                        out.append(self._reply(servo, *servo.read(address, length)))
                return out
            if inst == Instruction.FAST_BULK_READ:
                return self._fast_read(split_bulk_read(params), now)
            if inst == Instruction.BULK_WRITE:
                for servo_id, address, data in split_bulk_write(params):
                    servo = self._servo_for(servo_id, now)
                    if servo is not None:
                        servo.write(address, data)
                self._rebuild_ids()
                return []
            if inst == Instruction.PING:
                out = []
                for servo in self._listening(now):
                    out.append(self._reply(servo, *servo.ping()))
                for servo_id in sorted(self.faults.missing):
                    self.fault_counts["missing"] += 1
                    _ = servo_id
                return out
            if inst == Instruction.ACTION:
                for servo in self._listening(now):
                    servo.action()
                self._rebuild_ids()
                return []
            if inst == Instruction.REBOOT:
                for servo in self._listening(now):
                    servo.reboot(now)
                return []
            if inst in (Instruction.WRITE, Instruction.REG_WRITE) and len(params) >= 3:
                address = params[0] | params[1] << 8
                for servo in self._listening(now):
                    if inst == Instruction.WRITE:
                        servo.write(address, params[2:])
                    else:
                        servo.reg_write(address, params[2:])
                self._rebuild_ids()
                return []
        except PacketError:
            return []
        return []  # broadcast instructions get no status, even when wrong

    def _quick_goal_write(self, params: bytes, now: float) -> bool:
        """A Sync Write of Goal Position to servos that all hear it, done as the general
        path would do it; False (nothing done) when that path must handle it."""
        if len(params) < 9 or params[0] != GOAL_POSITION_ADDRESS or params[1] \
                or params[2] != 4 or params[3] or (len(params) - 4) % 5:
            return False
        body = params[4:]
        ids = body[::5]
        plan = self._write_plans.get(ids)
        if plan is None or plan.generation != self._generation \
                or plan.limits is not self.goal_limits:
            plan = write_plan(self._by_id, ids, self.goal_limits, self._generation)
            if plan is None:
                return False
            self._write_plans[ids] = plan
        outside = goals_heard(plan, body, now, self._baud_index(), self.compiled)
        if outside < 0:
            return False
        stats = self.stats
        stats.goals_decoded += len(ids)
        if self.goal_limits:
            stats.goals_outside += outside
        if self.on_sync_write is not None:
            self.on_sync_write(now, GOAL_POSITION_ADDRESS,
                               [(body[k], body[k + 1 : k + 5]) for k in range(0, len(body), 5)])
        write_goals(plan, body, now, self.compiled)
        return True

    def _quick_fast_read(self, params: bytes, now: float) -> list[_Reply] | None:
        """The reply to a Fast Sync Read every addressed servo answers normally (no reply
        fault, no mute switched on); None when the general path must answer it."""
        f = self._faults
        if f.mute or f.any_reply_fault or len(params) < 5:
            return None
        plan = self._read_plans.get(params)
        if plan is None or plan.generation != self._generation:
            address, length = params[0] | params[1] << 8, params[2] | params[3] << 8
            plan = read_plan(self._by_id, address, length, params[4:], self._generation)
            if plan is None:
                return None
            self._read_plans[params] = plan
        packet = answer_read(plan, now, self._baud_index(), self.compiled)
        if packet is None:
            return None
        return [_Reply(packet, plan.servos[0].return_delay_s)]

    def _fast_read(
        self, requests: Sequence[tuple[int, int, int]], now: float
    ) -> list[_Reply]:
        """One combined reply; it stops short at the first servo that does not answer.

        A request the reply cannot carry (a range beyond the control table, a reply
        longer than a packet) gets no reply at all."""
        if isinstance(requests, SyncReads):
            quick = self._quick_fast_read(requests.params, now)
            if quick is not None:
                return quick
        total = 8 + sum(n + 4 for _, _, n in requests)
        if total > MAX_PACKET_LEN or any(n == 0 or a + n > READABLE_BYTES
                                         for _, a, n in requests):
            return []
        chunks: list[tuple[int, int, bytes]] = []
        complete = True
        first_delay = 0.0
        for servo_id, address, length in requests:
            servo = self._servo_for(servo_id, now)
            if servo is None or servo.status_return_level < 1 \
                    or (self._faults.mute and self._muted(servo_id, now)):
                complete = False
                break
            if not chunks:
                first_delay = servo.return_delay_s
            err, data = servo.read(address, length)
            if not data:  # an error reply carries no data; keep the frame's shape
                data = bytes(length)
            chunks.append((servo_id, err, data))
        if not chunks:
            return []
        missing = [(i, 0, bytes(n)) for i, _, n in requests[len(chunks):]]
        sent = 8 + sum(len(d) + 4 for _, _, d in chunks)

        def build(first_id: int) -> bytes:
            first = (first_id, chunks[0][1], chunks[0][2])
            packet = build_fast_read_reply([first, *chunks[1:], *missing])
            return packet if complete else packet[:sent]

        packet = build(chunks[0][0])
        extra = 0.0
        if self.faults.any_reply_fault:
            packet, extra = self._apply_faults(packet, chunks[0][0], build)
        return [_Reply(packet, first_delay, extra)]
