"""An emulated Dynamixel Protocol 2.0 bus on a pseudo-terminal.

A client (``dynamixel-sdk``, or handrig's driver on top of it) opens
``bus.port_path`` as if it were a USB adapter. A thread reads the master side,
frames instruction packets by LEN (the SDK sends them unstuffed), checks the
CRC, dispatches to :class:`~sim.dxl_servo.EmulatedServo` objects and writes the
status packets back.

Wire time (``wire_timing=True``): a pty delivers bytes at once whatever the
baud rate, so the bus models the wire itself. It reads the baud the client set
(``termios.tcgetattr``), counts 10 bits per byte, and releases each reply no
earlier than the time the last byte would have arrived on a real half-duplex
bus: instruction on the wire, then the servo's Return Delay Time, then the reply.
Replies are held until that instant (sleep, then a short spin), never earlier.

Faults (:class:`FaultSpec`): dropped, CRC-corrupted, wrong-ID, truncated and
delayed replies with given probabilities (explicit seed), missing servos, and
an overload hardware error on chosen servos; every fault is counted in
:attr:`SimBus.fault_counts`.

Goal audit: every Goal Position the bus decodes (Sync Write or Write) is
counted in ``stats.goals_decoded``; with ``goal_limits`` (from the rig: each
calibrated servo's ``[min_deg, max_deg]`` in ticks) one outside them is counted
in ``stats.goals_outside``, the driver-side promise checked from the servo side.
"""

from __future__ import annotations

import dataclasses
import os
import random
import select
import termios
import threading
import tty
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Literal, NamedTuple, Protocol, cast

from firmware_protocol.dynamixel import (
    BAUD_BY_INDEX,
    BROADCAST_ID,
    MAX_PACKET_LEN,
    MODELS,
    ErrorCode,
    HardwareError,
    Instruction,
    PacketError,
    build_fast_read_reply,
    build_status,
    find_frame,
    parse_instruction,
    split_bulk_read,
    split_bulk_write,
    split_sync_read,
    split_sync_write,
)
from handrig.app.robots import load_rig
from handrig.clock import Clock, MonotonicClock
from handrig.config.rig import RigConfig
from handrig.errors import ConfigError
from handrig.realtime import LOOP_TIMER_SLACK_NS, timer_slack_ns
from sim.dxl_servo import READABLE_BYTES, EmulatedServo


class MotionModel(Protocol):
    """What moves the servos' motors (:class:`sim.puppet.Puppet`): it reads goals and
    writes present state through :meth:`EmulatedServo.set_motion`, holding ``lock``."""

    @property
    def driven_ids(self) -> Sequence[int]: ...

    def attach(self, servos: Sequence[EmulatedServo], lock: threading.RLock) -> None: ...

    def start(self) -> None: ...

    def stop(self) -> None: ...

BITS_PER_BYTE = 10  # start + 8 data + stop
# A partial frame older than this is dropped as line noise.
STALE_PARTIAL_S = 0.1
# Servos without physics move kinematically; their state is advanced at most this often.
KINEMATIC_STEP_S = 0.002
# Housekeeping (kinematic motion, watchdogs, overload; about 10 us per servo) runs
# in time the bus waits anyway: before a reply's wire instant when at least
# HOUSEKEEPING_SLOT_S is left, or while the line is idle; on a packet's arrival only
# once overdue by HOUSEKEEPING_OVERDUE_S (or always without wire timing). Never
# right after a reply: the pty hands bytes over through a kernel worker that may
# be queued on this thread's CPU, and a SCHED_FIFO thread that keeps working holds
# it back (docs/measurements.md has the hand-over times measured both ways).
HOUSEKEEPING_SLOT_S = 0.0003
HOUSEKEEPING_OVERDUE_S = 0.01
# Replies are timed by sleeping, then spinning for the last SPIN_S (with the thread's
# timer slack cut to 1 us, Linux sleeps overshoot by tens of microseconds).
SPIN_S = 60e-6


# SCHED_FIFO priority of the bus thread when ``realtime`` (low: above normal tasks only).
REALTIME_PRIORITY = 10


def _tighten_timer_slack() -> None:
    """Timer slack of 1 us for the calling thread (Linux; no-op elsewhere)."""
    timer_slack_ns(LOOP_TIMER_SLACK_NS)


def _try_realtime() -> bool:
    """SCHED_FIFO for the calling thread where allowed; False when refused or unsupported.

    On a loaded machine a normal thread wakes late from its sleeps, and its replies
    leave late (docs/measurements.md)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(REALTIME_PRIORITY))
    except (OSError, AttributeError):
        return False
    return True


def _baud_table() -> dict[int, int]:
    out: dict[int, int] = {}
    for name in dir(termios):
        if name.startswith("B") and name[1:].isdigit():
            out[getattr(termios, name)] = int(name[1:])
    return out


_BAUD_OF_SPEED = _baud_table()


@dataclass(frozen=True)
class FaultSpec:
    """Switchable faults. Probabilities are per reply; ``seed`` makes them repeatable.

    ``missing``: servo IDs that never answer (as if unplugged). ``overload``: servo
    IDs that report an overload hardware error ``overload_after_s`` after the bus
    starts (torque off, Alert bit set, only a reboot clears it). ``delay_s`` is the
    extra latency of a delayed reply.
    """

    drop: float = 0.0
    corrupt: float = 0.0
    wrong_id: float = 0.0
    truncate: float = 0.0
    delay: float = 0.0
    delay_s: float = 0.005
    missing: frozenset[int] = field(default_factory=frozenset)
    overload: frozenset[int] = field(default_factory=frozenset)
    overload_after_s: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("drop", "corrupt", "wrong_id", "truncate", "delay"):
            p = getattr(self, name)
            if not 0.0 <= p <= 1.0:
                raise ConfigError("fault probability out of range", key=name, value=p,
                                  allowed="0..1")
        if self.delay_s < 0 or self.overload_after_s < 0:
            raise ConfigError("times must be >= 0", key="delay_s/overload_after_s",
                              value=(self.delay_s, self.overload_after_s))

    @property
    def any_reply_fault(self) -> bool:
        return any((self.drop, self.corrupt, self.wrong_id, self.truncate, self.delay))

    @classmethod
    def parse(cls, spec: str) -> FaultSpec:
        """Parse ``"drop=0.02,corrupt=0.01,wrong_id=0.01,truncate=0.01,delay=0.01:0.005,
        missing=7+9,overload=3@1.5,seed=42"`` (any subset, comma separated).

        ``delay=P[:SECONDS]``; ``missing`` and ``overload`` take IDs joined by ``+``;
        ``overload=IDS[@SECONDS]``.
        """
        allowed = "drop, corrupt, wrong_id, truncate, delay=P[:S], missing=ID+ID, " \
                  "overload=ID+ID[@S], seed=N"
        kw: dict[str, object] = {}
        for part in filter(None, (p.strip() for p in spec.split(","))):
            key, eq, value = part.partition("=")
            key = key.strip().replace("-", "_")
            if not eq:
                raise ConfigError("expected key=value", file="--faults", key=part, allowed=allowed)
            try:
                if key in ("drop", "corrupt", "wrong_id", "truncate"):
                    kw[key] = float(value)
                elif key == "delay":
                    p, _, s = value.partition(":")
                    kw["delay"] = float(p)
                    if s:
                        kw["delay_s"] = float(s.removesuffix("s"))
                elif key == "missing":
                    kw["missing"] = frozenset(int(v) for v in value.split("+") if v)
                elif key == "overload":
                    ids, _, after = value.partition("@")
                    kw["overload"] = frozenset(int(v) for v in ids.split("+") if v)
                    if after:
                        kw["overload_after_s"] = float(after.removesuffix("s"))
                elif key == "seed":
                    kw["seed"] = int(value)
                else:
                    raise ConfigError("unknown fault", file="--faults", key=key, allowed=allowed)
            except ValueError as exc:
                raise ConfigError(f"bad number ({exc})", file="--faults", key=key, value=value,
                                  allowed=allowed) from None
        try:
            return cls(**kw)  # type: ignore[arg-type]
        except ConfigError as exc:
            raise exc.located("--faults") from None


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


class SimBus:
    """Emulated servos behind a pty. Use as a context manager::

        with SimBus.from_rig(load_rig_config(), puppet=True, wire_timing=True) as bus:
            port = PortHandler(bus.port_path)
            bus.servo(3).torque_enabled, bus.fault_counts, bus.stats

    ``servos``: the emulated servos (or a rig config: one servo per calibrated ID).
    ``wire_timing``: hold replies until their wire time at the client's baud rate.
    ``faults``: fault switches (:class:`FaultSpec`). ``puppet``: what moves the motors
    (:class:`sim.puppet.Puppet`); without one servos move kinematically.
    ``clock``: times replies (default: :class:`MonotonicClock` with a 60 us spin).
    ``check_baud``: a servo hears only packets sent at its Baud Rate item (off by
    default: servos follow whatever baud the client sets). ``realtime``: ask for
    SCHED_FIFO priority for the bus thread (best effort; ``realtime_granted`` says
    whether the OS agreed) so replies leave on time on a busy machine.

    ``on_sync_write(t_s, address, items)``, if set, is called from the bus thread for
    each Sync Write: ``t_s`` the clock time its bytes were read off the pty (with the
    default clock, CLOCK_MONOTONIC on Linux), its start address and its
    ``[(id, data bytes)]``. It is how a latency is measured from outside the rig.
    """

    def __init__(
        self,
        servos: Sequence[EmulatedServo] | RigConfig,
        *,
        wire_timing: bool = False,
        faults: FaultSpec | None = None,
        puppet: MotionModel | None = None,
        clock: Clock | None = None,
        check_baud: bool = False,
        realtime: bool = True,
    ) -> None:
        limits = goal_limits(servos) if isinstance(servos, RigConfig) else {}
        if isinstance(servos, RigConfig):
            servos = servos_from_rig(servos)
        if not servos:
            raise ConfigError("an emulated bus needs at least one servo", key="servos")
        ids = [s.id for s in servos]
        if len(set(ids)) != len(ids):
            raise ConfigError("servo ID used twice on the emulated bus", key="servos", value=ids)
        self.servos: list[EmulatedServo] = list(servos)
        self.wire_timing = wire_timing
        self.check_baud = check_baud
        self.realtime = realtime
        self.realtime_granted = False
        self._packet_baud = 0
        self._faults = faults or FaultSpec()
        self.puppet = puppet
        self.clock = clock or MonotonicClock(spin_s=SPIN_S)
        self.lock = threading.RLock()
        self.fault_counts: Counter[str] = Counter()
        self.stats = BusStats()
        self.port_path = ""
        self._rng = random.Random(self._faults.seed)
        self._by_id: dict[int, EmulatedServo] = {}
        self._rebuild_ids()
        self._master = -1
        self._slave = -1
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._started_at = 0.0
        self._overload_done = False
        self._bus_free_at = 0.0
        self._last_advance = 0.0
        self._kinematic: list[EmulatedServo] = []
        self._partial_since: float | None = None
        self._feed_buf = bytearray()
        self.error: BaseException | None = None
        self.goal_limits: dict[int, tuple[int, int]] = limits
        """Servo ID -> (lowest, highest) Goal Position ticks it may be sent."""
        self.on_sync_write: Callable[[float, int, list[tuple[int, bytes]]], None] | None = None

    # --------------------------------------------------------------- building

    @classmethod
    def from_rig(
        cls,
        rig: RigConfig | str | Path | None = None,
        *,
        ids: Sequence[int] | None = None,
        model: str | None = None,
        puppet: bool | MotionModel = False,
        wire_timing: bool = False,
        faults: FaultSpec | None = None,
        clock: Clock | None = None,
        realtime: bool = True,
    ) -> SimBus:
        """Servos for the rig's IDs (or ``ids``), each starting at its joint's zero.

        ``puppet=True`` attaches a MuJoCo hand (:class:`sim.puppet.Puppet`) whose joints
        the calibrated servos drive; IDs without a calibration move kinematically.
        """
        # a path or preset name; a robot rig ("leap") brings its own MJCF model
        config = rig if isinstance(rig, RigConfig) else load_rig(rig)
        if model is not None:
            config = with_model(config, model)
        servos = servos_from_rig(config, ids=ids, model=model)
        the_puppet: MotionModel | None
        if puppet is True:
            from sim.puppet import Puppet

            the_puppet = Puppet(config)
        elif puppet is False:
            the_puppet = None
        else:
            the_puppet = puppet
        bus = cls(servos, wire_timing=wire_timing, faults=faults, puppet=the_puppet,
                  clock=clock, realtime=realtime)
        bus.goal_limits = goal_limits(config)
        return bus

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

    # ------------------------------------------------------------ lifecycle

    def start(self) -> SimBus:
        """Open the pty and start serving; ``port_path`` is then valid."""
        if self._thread is not None:
            return self
        self._master, self._slave = os.openpty()
        tty.setraw(self._master)
        tty.setraw(self._slave)
        self.port_path = os.ttyname(self._slave)
        self._started_at = self.clock.now()
        self._last_advance = self._started_at
        for s in self.servos:
            s.last_heard = self._started_at
        driven = set()
        if self.puppet is not None:
            self.puppet.attach(self.servos, self.lock)
            driven = set(self.puppet.driven_ids)
            self.puppet.start()
        self._kinematic = [s for s in self.servos if s.id not in driven]
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, name="dxl-sim-bus", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving and close the pty."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self.puppet is not None:
            self.puppet.stop()
        for fd in (self._master, self._slave):
            if fd >= 0:
                os.close(fd)
        self._master = self._slave = -1

    def __enter__(self) -> SimBus:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def baud(self) -> int:
        """The baud rate the client set on the port (termios), 1 Mbps if unknown."""
        try:
            speed = termios.tcgetattr(self._master)[5]
        except (termios.error, OSError):
            return 1_000_000
        return _BAUD_OF_SPEED.get(speed, 1_000_000) or 1_000_000

    # ------------------------------------------------------------- serving

    def _serve(self) -> None:
        _tighten_timer_slack()
        if self.realtime:
            self.realtime_granted = _try_realtime()
        buf = bytearray()
        last_rx = 0.0
        fd = self._master
        clock = self.clock
        try:
            while not self._stop.is_set():
                # Arrivals are time-stamped before anything else.
                ready, _, _ = select.select([fd], [], [], 0.01)
                now = clock.now()
                if not ready:
                    self._housekeeping(now)
                    if buf and now - last_rx > STALE_PARTIAL_S:
                        self.stats.noise_bytes += len(buf)
                        buf.clear()
                        self._partial_since = None
                    continue
                try:
                    chunk = os.read(fd, 65536)
                except OSError:
                    continue
                last_rx = now
                buf += chunk
                self._drain(buf, now)  # then straight back to select: see HOUSEKEEPING_SLOT_S
        except BaseException as exc:  # reported through .error; the thread must not vanish
            self.error = exc
            raise

    def _drain(self, buf: bytearray, now: float) -> None:
        """Handle every complete frame in ``buf``; keep a partial one for later.

        A partial frame that stays incomplete for ``STALE_PARTIAL_S`` while bytes keep
        coming (a corrupted LEN) is given up: its header is skipped and framing
        resumes at the next header."""
        pos = 0
        while True:
            found = find_frame(buf, pos)
            if found is None:
                head = buf.find(b"\xff\xff\xfd\x00", pos)
                if head < 0:
                    keep = min(3, len(buf) - pos)  # the start of a header may be there
                    self.stats.noise_bytes += len(buf) - keep - pos
                    del buf[: len(buf) - keep]
                    self._partial_since = None
                    return
                self.stats.noise_bytes += head - pos
                del buf[:head]
                if self._partial_since is None:
                    self._partial_since = now
                elif now - self._partial_since > STALE_PARTIAL_S:
                    self.stats.noise_bytes += 1
                    self._partial_since = None
                    pos = 1
                    continue
                return
            begin, end = found
            self._partial_since = None
            self.stats.noise_bytes += begin - pos
            self._handle_frame(bytes(buf[begin:end]), now)
            pos = end

    def _housekeeping(self, now: float) -> None:
        f = self.faults
        if f.overload and not self._overload_done and now - self._started_at >= f.overload_after_s:
            with self.lock:
                for s in self.servos:
                    if s.id in f.overload:
                        s.inject_hardware_error(HardwareError.OVERLOAD)
                        self.fault_counts["overload"] += 1
            self._overload_done = True
        if now - self._last_advance >= KINEMATIC_STEP_S:
            dt = now - self._last_advance
            self._last_advance = now
            with self.lock:
                for s in self._kinematic:
                    s.advance(dt)
                for s in self.servos:
                    s.check_watchdog(now)

    def _handle_frame(self, frame: bytes, t_rx: float) -> None:
        self.stats.packets += 1
        if self.check_baud:
            self._packet_baud = self.baud()
        with self.lock:
            if not self.wire_timing or t_rx - self._last_advance >= HOUSEKEEPING_OVERDUE_S:
                self._housekeeping(t_rx)
            try:
                packet = parse_instruction(frame)
            except PacketError as exc:
                replies: list[_Reply] = []
                if exc.kind == "crc":
                    self.stats.bad_crc += 1
                    servo = self._servo_for(frame[4], t_rx)
                    if servo is not None:
                        err = servo.error_byte(ErrorCode.CRC)
                        replies = [self._reply(servo, err)]
            else:
                self.stats.by_instruction[packet.instruction] += 1
                replies = self._dispatch(packet.id, packet.instruction, packet.params, t_rx)
        ready = self.clock.now()
        overhead = ready - t_rx
        self.stats.overhead_total_s += overhead
        self.stats.overhead_max_s = max(self.stats.overhead_max_s, overhead)
        self._send(replies, len(frame), t_rx)

    def _send(self, replies: list[_Reply], frame_len: int, t_rx: float) -> None:
        """Write replies; with wire timing, each when its last byte would arrive."""
        if not self.wire_timing:
            for r in replies:
                if r.fault_delay_s:
                    self.clock.sleep(r.fault_delay_s)
                if r.data:
                    self._emit(r.data)
                    self.stats.replies += 1
            return
        byte_s = BITS_PER_BYTE / self.baud()
        t = max(t_rx, self._bus_free_at) + frame_len * byte_s
        if replies:
            first = replies[0]
            first_at = t + first.return_delay_s + first.fault_delay_s + len(first.data) * byte_s
            now = self.clock.now()
            if first_at - now >= HOUSEKEEPING_SLOT_S:
                self._housekeeping(now)  # in the reply's wire time, not after it
        for r in replies:
            t += r.return_delay_s + r.fault_delay_s + len(r.data) * byte_s
            if r.data:
                self.clock.sleep_until(t)
                self._emit(r.data)
                late = self.clock.now() - t
                self.stats.replies += 1
                self.stats.late_total_s += late
                self.stats.late_max_s = max(self.stats.late_max_s, late)
        self._bus_free_at = t

    def _emit(self, data: bytes) -> None:
        """Put bytes on the line (the pty master)."""
        os.write(self._master, data)

    def feed(self, data: bytes, now: float | None = None) -> None:
        """Handle bytes as if they had arrived on the line (no pty, no thread needed);
        replies go through :meth:`_emit`."""
        self._feed_buf += data
        self._drain(self._feed_buf, self.clock.now() if now is None else now)

    # ------------------------------------------------------------ dispatch

    def _reply(self, servo: EmulatedServo, error: int, data: bytes = b"") -> _Reply:
        """One status packet, with faults applied."""
        packet = build_status(servo.id, error, data)
        extra = 0.0
        if self.faults.any_reply_fault:
            packet, extra = self._apply_faults(
                packet, servo.id, lambda other: build_status(other, error, data))
        return _Reply(packet, servo.return_delay_s, extra)

    def _apply_faults(
        self, packet: bytes, servo_id: int, rebuild: Callable[[int], bytes]
    ) -> tuple[bytes, float]:
        """Drop, misaddress (``rebuild(other_id)``), corrupt, truncate or delay a reply."""
        f = self.faults
        rng = self._rng
        if f.drop and rng.random() < f.drop:
            self.fault_counts["dropped"] += 1
            return b"", 0.0
        if f.wrong_id and rng.random() < f.wrong_id:
            self.fault_counts["wrong_id"] += 1
            other = rng.choice([i for i in range(253) if i != servo_id])
            packet = rebuild(other)
        if f.corrupt and rng.random() < f.corrupt:
            self.fault_counts["corrupted"] += 1
            packet = packet[:-1] + bytes((packet[-1] ^ 0x5A,))
        if f.truncate and rng.random() < f.truncate:
            self.fault_counts["truncated"] += 1
            packet = packet[: rng.randrange(1, len(packet))]
        extra = 0.0
        if f.delay and rng.random() < f.delay:
            self.fault_counts["delayed"] += 1
            extra = f.delay_s
        return packet, extra

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
        """With ``check_baud``, a servo hears only packets at its Baud Rate item."""
        return not self.check_baud or BAUD_BY_INDEX.get(servo.mem[8]) == self._packet_baud

    def _listening(self, now: float) -> list[EmulatedServo]:
        """Servos that hear a broadcast now, in ID order."""
        return sorted((s for s in self._by_id.values() if s.available(now) and self._hears(s)),
                      key=lambda s: s.id)

    def _dispatch(
        self, target: int, inst: int, params: bytes, now: float
    ) -> list[_Reply]:
        if target == BROADCAST_ID:
            for s in self._by_id.values():
                if self._hears(s):
                    s.last_heard = now
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
                return [self._reply(servo, err)] if level >= 2 else []
            if inst == Instruction.ACTION:
                err = servo.action()
                self._rebuild_ids()
                return [self._reply(servo, err)] if level >= 2 else []
            if inst == Instruction.REBOOT:
                err = servo.reboot(now)
                return [self._reply(servo, err)] if level >= 2 else []
            if inst == Instruction.FACTORY_RESET:
                option = params[0] if len(params) == 1 else 0
                reply = [self._reply(servo, servo.factory_reset(option, now))] if level >= 2 else []
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
                address, length, ids = split_sync_read(params)
                return self._fast_read([(i, address, length) for i in ids], now)
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

    def _fast_read(
        self, requests: Sequence[tuple[int, int, int]], now: float
    ) -> list[_Reply]:
        """One combined reply; it stops short at the first servo that does not answer.

        A request the reply cannot carry (a range beyond the control table, a reply
        longer than a packet) gets no reply at all."""
        total = 8 + sum(n + 4 for _, _, n in requests)
        if total > MAX_PACKET_LEN or any(n == 0 or a + n > READABLE_BYTES
                                         for _, a, n in requests):
            return []
        chunks: list[tuple[int, int, bytes]] = []
        complete = True
        first_delay = 0.0
        for servo_id, address, length in requests:
            servo = self._servo_for(servo_id, now)
            if servo is None or servo.status_return_level < 1:
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


def with_model(config: RigConfig, model: str) -> RigConfig:
    """The rig with every servo of model ``model`` (servos and puppet must agree)."""
    if model not in MODELS:
        raise ConfigError("unknown servo model", key="model", value=model,
                          allowed=", ".join(MODELS))
    name = cast(Literal["XL330-M288", "XC330-T288", "XM430-W350", "XC330-M288"], model)
    return dataclasses.replace(config, servos=tuple(
        dataclasses.replace(s, model=name) for s in config.servos))


GOAL_POSITION_ADDRESS = 116  # Goal Position (REFERENCE.md section 2)


def goal_limits(config: RigConfig) -> dict[int, tuple[int, int]]:
    """Each calibrated servo's ``[min_deg, max_deg]`` as (lowest, highest) goal ticks."""
    out = {}
    for s in config.servos:
        a, b = s.deg_to_ticks(s.min_deg), s.deg_to_ticks(s.max_deg)
        out[s.id] = (min(a, b), max(a, b))
    return out


def servos_from_rig(
    config: RigConfig, *, ids: Sequence[int] | None = None, model: str | None = None
) -> list[EmulatedServo]:
    """Emulated servos for a rig: its IDs (or ``ids``), its models (or ``model``),
    each starting at its calibrated zero (joint at 0 deg)."""
    calibrated = {s.id: s for s in config.servos}
    wanted = list(ids) if ids is not None else list(calibrated)
    out = []
    for servo_id in wanted:
        cal = calibrated.get(servo_id)
        out.append(EmulatedServo(
            servo_id,
            model or (cal.model if cal else "XL330-M288"),
            baud=config.bus.baud,
            start_ticks=float(cal.zero_ticks) if cal else 2048.0,
        ))
    return out
