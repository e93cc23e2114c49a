"""An emulated Dynamixel Protocol 2.0 bus on a pseudo-terminal.

A client (``dynamixel-sdk``, or handrig's driver on top of it) opens
``bus.port_path`` as if it were a USB adapter. A thread reads the emulator's end
of the pty (:class:`sim.dxl_line.PtyLine`: it holds no end a client opens),
frames instruction packets by LEN (the SDK sends them unstuffed), checks the
CRC, dispatches to :class:`~sim.dxl_servo.EmulatedServo` objects
(:class:`sim.dxl_dispatch.Dispatcher`) and writes the status packets back.

Wire time (``wire_timing=True``): a pty delivers bytes at once whatever the
baud rate, so the bus models the wire itself. It reads the baud the client set
(``termios.tcgetattr``), counts 10 bits per byte, and releases each reply no
earlier than the time the last byte would have arrived on a real half-duplex
bus: instruction on the wire, then the servo's Return Delay Time, then the reply.
Replies are held until that instant (sleep, then a short spin), never earlier.

Faults: :class:`sim.dxl_faults.FaultSpec`. Servos for a rig: :mod:`sim.dxl_rig`.
"""

from __future__ import annotations

import random
import threading
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Protocol

from firmware_protocol.dynamixel import (
    ErrorCode,
    HardwareError,
    PacketError,
    find_frame,
)
from handrig.clock import Clock, MonotonicClock
from handrig.config.rig import RigConfig
from handrig.errors import ConfigError
from handrig.pose.robot_rig import load_rig
from handrig.realtime import SHORT_SLICE_NS, fair_slice_ns
from sim.dxl_dispatch import BusStats, Dispatcher, _Reply
from sim.dxl_fast import parse_frame
from sim.dxl_faults import FaultSpec
from sim.dxl_line import BITS_PER_BYTE, SPIN_S, PtyLine, tighten_timer_slack, try_realtime
from sim.dxl_rig import GOAL_POSITION_ADDRESS, goal_limits, servos_from_rig, with_model
from sim.dxl_servo import EmulatedServo

__all__ = [
    "BITS_PER_BYTE", "GOAL_POSITION_ADDRESS", "BusStats", "FaultSpec", "MotionModel", "SimBus",
    "_Reply", "goal_limits", "servos_from_rig", "with_model",
]


class MotionModel(Protocol):
    """What moves the servos' motors (:class:`sim.puppet.Puppet`): it reads goals and
    writes present state through :meth:`EmulatedServo.set_motion`, holding ``lock``."""

    @property
    def driven_ids(self) -> Sequence[int]: ...

    def attach(self, servos: Sequence[EmulatedServo], lock: threading.RLock) -> None: ...

    def start(self, *, exchanged: bool = False, realtime: bool = False) -> None: ...

    def exchange(self) -> bool: ...

    def stop(self) -> None: ...


# A partial frame older than this is dropped as line noise.
STALE_PARTIAL_S = 0.1
# Servos without physics move kinematically; their state is advanced at most this often.
KINEMATIC_STEP_S = 0.002
# Housekeeping (kinematic motion or the puppet's exchange, watchdogs, overload; about
# 4-10 us per servo) runs in time the bus waits anyway: before a reply's wire instant
# when at least HOUSEKEEPING_SLOT_S is left, or while the line is idle (never while a
# packet without reply is on the wire: the client's next packet would wait behind it,
# stamped late; a rule that also asked for the time it last took left it out of the
# slots on a busy machine: motion every 10 ms); on a packet's arrival only
# once overdue by HOUSEKEEPING_OVERDUE_S (or always without wire timing). Never
# right after a reply: the pty hands bytes over through a kernel worker that may
# be queued on this thread's CPU, and a SCHED_FIFO thread that keeps working holds
# it back (docs/measurements.md has the hand-over times measured both ways).
HOUSEKEEPING_SLOT_S = 0.0003
HOUSEKEEPING_OVERDUE_S = 0.01
# An idle line (no bytes) is looked at again this often for housekeeping.
IDLE_WAIT_S = 0.01


class SimBus(Dispatcher):
    """Emulated servos behind a pty. Use as a context manager::

        with SimBus.from_rig(load_rig_config(SHIPPED_RIG), puppet=True, wire_timing=True) as bus:
            port = PortHandler(bus.port_path)
            bus.servo(3).torque_enabled, bus.fault_counts, bus.stats

    ``servos``: the emulated servos (or a rig config: one servo per calibrated ID).
    ``wire_timing``: hold replies until their wire time at the client's baud rate.
    ``faults``: fault switches (:class:`FaultSpec`). ``puppet``: what moves the motors
    (:class:`sim.puppet.Puppet`); without one servos move kinematically.
    ``clock``: times replies (default: :class:`MonotonicClock` with a 60 us spin).
    ``check_baud``: a servo hears only packets sent at its Baud Rate item, as a real
    one does (on by default; off, servos follow whatever baud the client sets).
    ``realtime``: ask for
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
        check_baud: bool = True,
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
        self._line_baud = 0  # the client's baud when the packet being handled was read
        self._faults = faults or FaultSpec()
        self.puppet = puppet
        self.clock = clock or MonotonicClock(spin_s=SPIN_S)
        self.lock = threading.RLock()
        self.fault_counts: Counter[str] = Counter()
        self.stats = BusStats()
        self.port_path = ""
        self._rng = random.Random(self._faults.seed)
        self._by_id: dict[int, EmulatedServo] = {}
        self._generation = 0
        self._rebuild_ids()
        self.line = PtyLine()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._started_at = 0.0
        self._overload_done = False
        self._bus_free_at = 0.0
        self._last_advance = 0.0
        self._last_exchange = 0.0  # when the puppet last exchanged state with the servos
        self._in_packet = False  # housekeeping runs in a packet's path (no slot)
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
        bauds: Mapping[int, int] | None = None,
    ) -> SimBus:
        """Servos for the rig's IDs (or ``ids``), each starting at its joint's zero.

        ``puppet=True`` attaches a MuJoCo hand (:class:`sim.puppet.Puppet`) whose joints
        the calibrated servos drive; IDs without a calibration move kinematically.
        ``bauds``: servo ID -> baud (bits per second) for servos not at the rig's baud.
        """
        # a path or preset name; a robot rig ("leap") brings its own MJCF model
        config = rig if isinstance(rig, RigConfig) else load_rig(rig)
        if model is not None:
            config = with_model(config, model)
        servos = servos_from_rig(config, ids=ids, model=model, bauds=bauds)
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

    # ------------------------------------------------------------ lifecycle

    def start(self) -> SimBus:
        """Open the pty and start serving; ``port_path`` is then valid."""
        if self._thread is not None:
            return self
        self.port_path = self.line.open()
        self._started_at = self.clock.now()
        self._last_advance = self._started_at
        for s in self.servos:
            s.last_heard = self._started_at
            if s.id in self.faults.hot:
                s.warm_to(self.faults.hot_c)
                self.fault_counts["hot at start"] += 1
        driven = set()
        if self.puppet is not None:
            self.puppet.attach(self.servos, self.lock)
            driven = set(self.puppet.driven_ids)
            self.puppet.start(exchanged=True, realtime=self.realtime)
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
        self.line.close()

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
        return self.line.baud()

    @property
    def uptime_s(self) -> float:
        """Seconds since :meth:`start` on the bus's clock: where fault windows (``mute``,
        ``overload``) are counted from."""
        return self.clock.now() - self._started_at

    @property
    def client_open(self) -> bool:
        """Whether a client holds the port now."""
        return self.line.client_open

    @property
    def client_sessions(self) -> int:
        """How many times a client opened the port since :meth:`start`."""
        return self.line.sessions

    @property
    def client_closes(self) -> int:
        """How many times a client let the port go since :meth:`start`."""
        return self.line.closes

    # ------------------------------------------------------------- serving

    def _serve(self) -> None:
        tighten_timer_slack()
        if self.realtime:
            self.realtime_granted = try_realtime()
            if not self.realtime_granted:  # woken by a packet, run ahead of busy threads
                fair_slice_ns(SHORT_SLICE_NS)  # (the physics' among them; best effort)
        buf = bytearray()
        last_rx = 0.0
        line = self.line
        clock = self.clock
        # the physics waits for its exchanges (housekeeping): an idle line wakes for them
        idle_s = KINEMATIC_STEP_S if self.puppet is not None else IDLE_WAIT_S
        try:
            while not self._stop.is_set():
                chunk, closed = line.wait(idle_s)
                # Arrivals are time-stamped before anything else.
                now = clock.now()
                if closed:  # the client let the port go: what it left half-sent is noise
                    self.stats.noise_bytes += len(buf)
                    buf.clear()
                    self._partial_since = None
                if not chunk:
                    self._housekeeping(now)
                    if buf and now - last_rx > STALE_PARTIAL_S:
                        self.stats.noise_bytes += len(buf)
                        buf.clear()
                        self._partial_since = None
                    continue
                last_rx = now
                buf += chunk
                self._drain(buf, now)  # then straight back to the line: see HOUSEKEEPING_SLOT_S
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
        """Faults due, kinematic motion, watchdogs, and the puppet's exchange of goals and
        present state (in a packet's path, ``_in_packet``, only once overdue)."""
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
                if self.puppet is not None and (
                        not self._in_packet
                        or now - self._last_exchange >= HOUSEKEEPING_OVERDUE_S):
                    self._last_exchange = now
                    self.puppet.exchange()
                for s in self._kinematic:
                    s.advance(dt)
                for s in self.servos:
                    s.check_watchdog(now)

    def _handle_frame(self, frame: bytes, t_rx: float) -> None:
        self.stats.packets += 1
        # bytes fed without a line (:meth:`feed`) reach every servo
        self._line_baud = self.line.baud() if self.line.fd >= 0 else 0
        if self.check_baud:
            self._packet_baud = self._line_baud
        with self.lock:
            if not self.wire_timing or t_rx - self._last_advance >= HOUSEKEEPING_OVERDUE_S:
                self._in_packet = True
                try:
                    self._housekeeping(t_rx)
                finally:
                    self._in_packet = False
            try:
                packet = parse_frame(frame, self.compiled)
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
        self.stats.note_overhead(self.clock.now() - t_rx)
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
        byte_s = BITS_PER_BYTE / (self._line_baud or self.baud())
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
        self.line.write(data)

    def feed(self, data: bytes, now: float | None = None) -> None:
        """Handle bytes as if they had arrived on the line (no pty, no thread needed);
        replies go through :meth:`_emit`."""
        self._feed_buf += data
        self._drain(self._feed_buf, self.clock.now() if now is None else now)
