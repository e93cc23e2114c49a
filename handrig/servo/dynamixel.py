"""``DynamixelBus``: X-series servos on one Protocol 2.0 bus, through dynamixel-sdk.

What this adds to the SDK (REFERENCE.md section 1): deadlines on the injected
monotonic clock instead of the 34 ms busy-wait; each servo's ERR byte kept from
a Fast Sync Read, whose per-servo running CRCs are checked so a truncated or
partly corrupted reply still yields the servos before the damage; no crash on a
malformed or short reply; a lock instead of the ``is_using`` flag; stale
readings marked; a reply arriving after its read gave up recognised (each read
asks for the servos in another order) and never taken for a later read's; faults
counted, decoded and handled by a :class:`FaultPolicy`; torque only inside
:meth:`DynamixelBus.torque`, with the Bus Watchdog armed, checked and re-armed.

Units: see :mod:`handrig.servo.bus`. Goal positions go out as ticks
(``RigConfig`` calibration) and are clamped to each servo's ``[min_deg, max_deg]``
and to 0..4095 ticks whatever the caller asks.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
from collections.abc import Callable
from types import FrameType, TracebackType
from typing import Literal

import numpy as np

from handrig import kernels
from handrig.clock import Clock, MonotonicClock
from handrig.errors import DeviceError, DeviceTimeoutError, ProtocolError, SafetyStop, ServoFault
from handrig.rigconfig import MODEL_NUMBERS, POSITION_TICKS_MAX, TICKS_PER_DEG, RigConfig
from handrig.servo.bus import BusStats, FaultPolicy, ServoBus, ServoState
from handrig.servo.packets import (
    BROADCAST_ID,
    HEADER,
    INST_FAST_SYNC_READ,
    INST_PING,
    INST_READ,
    INST_REBOOT,
    INST_SYNC_READ,
    INST_SYNC_WRITE,
    INST_WRITE,
    StatusPacket,
    build_instruction,
    fast_sync_intact,
    fast_sync_valid,
    packet_length,
    parse_status,
    sdk_crc16,
    u16,
)
from handrig.servo.registers import (
    BUS_WATCHDOG_TRIPPED,
    BUS_WATCHDOG_UNIT_MS,
    CURRENT_MA_PER_UNIT,
    ERR_ALERT,
    OPERATING_MODE_POSITION,
    STATUS_RETURN_ALL,
    VELOCITY_DPS_PER_UNIT,
    Reg,
    describe_hardware_error,
    describe_status_error,
)
from handrig.servo.transport import SerialTransport

log = logging.getLogger("handrig.servo")

BITS_PER_BYTE = 10  # 8N1 on the wire
ORDERS = 64  # servo orders a Fast Sync Read cycles through (late replies are told apart)
COMMAND_TIMEOUT_S = 0.05  # a single command's reply: RDT 0.5 ms + a 16 ms latency timer, ample
# Commissioning sends ~6 commands per servo: with 20 servos and one reply in five
# lost, 3 attempts would fail a connect more often than not; 8 make it rare.
COMMAND_ATTEMPTS = 8
TORQUE_ON_SLACK_DEG = 1.0  # torque-on tolerates this much outside the limits (then clamps)
MAX_APPROACH_DEG = 20.0  # further out than this at torque-on: refuse (likely a wrong zero)
APPROACH_DPS = 30.0  # joint speed that brings a servo resting outside its limits back in
# A goal write after a silence this fraction of the Bus Watchdog time re-arms it first
# (the servo's clock and ours differ; a 200 Hz loop is silent 5 ms, far below).
WATCHDOG_GAP_FRACTION = 0.8
# Fast Sync Read replies are polled for (DynamixelBus spin_s) from REPLY_POLL_LEAD_S
# before the instant the wire delivers them until REPLY_POLL_AFTER_S after it (the
# pty or USB hand-over and the servos' own lateness), then waited for asleep.
REPLY_POLL_LEAD_S = 50e-6
REPLY_POLL_AFTER_S = 300e-6

ReadFields = Literal["position", "motion"]
# Contiguous control-table spans read each cycle: position only, or current+velocity+position.
_READ_SPANS: dict[str, tuple[int, int]] = {
    "position": (Reg.PRESENT_POSITION.address, 4),
    "motion": (Reg.PRESENT_CURRENT.address, 10),
}


_KERNEL_CRC_CHECKED = False


def _check_kernel_crc() -> None:
    """The compiled CRC (goal packets, whole Fast Sync Read replies) must equal
    dynamixel-sdk's ``updateCRC``; checked once per process, RuntimeError if not."""
    global _KERNEL_CRC_CHECKED
    if _KERNEL_CRC_CHECKED:
        return
    probe = bytes(range(256)) + b"\xff\xff\xfd\x00\xfe\x55"
    data = np.frombuffer(probe, np.uint8)
    for n in (0, 1, 7, 77, len(probe)):
        if kernels.crc16(data, n) != sdk_crc16(probe[:n]):
            raise RuntimeError("handrig.kernels.crc16 disagrees with dynamixel-sdk's updateCRC")
    _KERNEL_CRC_CHECKED = True


def wire_time_s(n_bytes: int, baud: int) -> float:
    """Time ``n_bytes`` take on the wire at ``baud`` (10 bits per byte)."""
    return n_bytes * BITS_PER_BYTE / baud


def cycle_bytes(n_servos: int, data_len: int = 4) -> int:
    """Bytes per write + Fast Sync Read cycle (REFERENCE.md section 3).

    Sync Write of Goal Position 14 + 5N, Fast Sync Read instruction 14 + N, its
    reply 8 + (data_len + 4) N (8 + 8N for the 4-byte position).
    """
    return (14 + 5 * n_servos) + (14 + n_servos) + (8 + (data_len + 4) * n_servos)


class DynamixelBus(ServoBus):
    """The servos of ``rig`` on the serial port ``port`` (a path such as ``/dev/ttyUSB0``).

    ``baud`` defaults to ``rig.bus.baud``; ``clock`` to :class:`MonotonicClock`.
    ``read_fields`` picks what each read fetches: ``"motion"`` (current, velocity
    and position, 10 bytes per servo) or ``"position"`` (4 bytes: the shortest
    cycle). ``temperature_every``: every that many state reads, when the read's
    deadline leaves time, one more Fast Sync Read fetches the temperatures and,
    with torque on, another checks the Bus Watchdogs and re-arms any that
    tripped (0: never). ``reply_timeout_s`` bounds the wait for one reply (default:
    twice its wire time plus 2 ms); ``reply_gap_s`` ends a reply that stops
    flowing (default 1.5 ms plus 32 byte times). ``spin_s``: poll for a Fast Sync
    Read reply, instead of sleeping, from ``spin_s`` before the instant the wire
    would deliver it until ``REPLY_POLL_AFTER_S`` after (0: always sleep). A
    sleeping thread takes tens of microseconds to wake, and wakes with cold
    caches; the poll costs about ``spin_s`` plus the reply's lateness in CPU per
    read. Against the emulator (``handrig bench bus``, 4 Mbps, 20 servos, 2-core
    VM, timer slack 1 us as in :func:`~handrig.realtime.pinned_loop`, 10 runs):
    0.85-0.87 of the wire limit always sleeping, at 72-87 us CPU per cycle;
    0.88-0.90 with the default 50 us, at 129-155 us. Pass 0 from a SCHED_FIFO
    thread that shares its CPU with the kernel's workers: while it polls, the
    worker that would deliver the reply cannot run there (the live loop does, see
    handrig.live).
    """

    def __init__(
        self,
        port: str,
        rig: RigConfig,
        *,
        baud: int | None = None,
        clock: Clock | None = None,
        fault_policy: FaultPolicy | None = None,
        read_fields: ReadFields = "motion",
        temperature_every: int = 100,
        reply_timeout_s: float | None = None,
        spin_s: float = REPLY_POLL_LEAD_S,
        reply_gap_s: float | None = None,
    ) -> None:
        if not rig.servos:
            raise DeviceError("the rig config lists no servos: add [[servos]] to config/rig.toml")
        if read_fields not in _READ_SPANS:
            raise ValueError(f"read_fields must be one of {sorted(_READ_SPANS)}")
        self.port = port
        self.rig = rig
        self.baud = int(baud if baud is not None else rig.bus.baud)
        self.clock = clock or MonotonicClock()
        self.policy = fault_policy or FaultPolicy()
        self.temperature_every = int(temperature_every)
        self._next_temperature_read = 0
        self._transport = SerialTransport(port, self.baud, self.clock)
        self._lock = threading.RLock()

        servos = rig.servos
        n = len(servos)
        self._n = n
        self.ids: tuple[int, ...] = tuple(s.id for s in servos)
        self._names: tuple[str, ...] = tuple(s.joint for s in servos)
        self._index_of_id = {s.id: i for i, s in enumerate(servos)}
        self._min_deg = np.array([s.min_deg for s in servos], np.float64)
        self._max_deg = np.array([s.max_deg for s in servos], np.float64)
        self._zero_ticks = np.array([s.zero_ticks for s in servos], np.float64)
        # ticks per joint degree, signed by direction
        self._ticks_per_deg = np.array(
            [s.direction * s.gear_ratio * TICKS_PER_DEG for s in servos], np.float64
        )
        self._expected_models = tuple(MODEL_NUMBERS[s.model] for s in servos)
        self._current_ma_per_unit = np.array(
            [CURRENT_MA_PER_UNIT.get(m, 1.0) for m in self._expected_models], np.float64
        )
        self._hold_deg = np.clip(0.0, self._min_deg, self._max_deg)
        # joint deg/s per Present Velocity unit: servo deg/s over (direction * gear ratio)
        self._dps_per_unit = VELOCITY_DPS_PER_UNIT * TICKS_PER_DEG / self._ticks_per_deg
        # the same four as rows of one array, for kernels.fast_sync_whole (views from now on)
        self._scale = np.stack([self._zero_ticks, self._ticks_per_deg, self._dps_per_unit,
                                self._current_ma_per_unit])
        (self._zero_ticks, self._ticks_per_deg, self._dps_per_unit,
         self._current_ma_per_unit) = self._scale

        # -- goal Sync Write: constant prefix, CRC resumed after it each cycle
        body_len = 5 * n
        length = 1 + 4 + body_len + 2
        self._sw_prefix = HEADER + bytes((BROADCAST_ID, length & 0xFF, length >> 8)) + bytes(
            (INST_SYNC_WRITE,)
        ) + u16(Reg.GOAL_POSITION.address) + u16(4)
        kernels.warm_up()
        _check_kernel_crc()
        # the whole goal Sync Write, rebuilt in place each cycle (kernels.goal_packet)
        self._sw_packet = np.zeros(kernels.SYNC_WRITE_BODY + body_len + 2, np.uint8)
        self._sw_packet[: len(self._sw_prefix)] = np.frombuffer(self._sw_prefix, np.uint8)
        self._sw_packet[kernels.SYNC_WRITE_BODY :: 5][:n] = self.ids
        self._sw_view = self._sw_packet.data  # a memoryview: what is written to the port
        self._rehearsal_packet = self._sw_packet.copy()
        self._goal_deg = np.zeros(n, np.float64)
        self._last_goal_deg = np.full(n, np.nan)
        self._rehearsal_goal = np.zeros(n, np.float64)
        # Profile Velocity units (0.229 rpm of the servo) for APPROACH_DPS of the joint
        self._approach_units = [
            max(1, round(APPROACH_DPS * abs(t) / TICKS_PER_DEG / VELOCITY_DPS_PER_UNIT))
            for t in self._ticks_per_deg]
        self.hold_outside_limits = False
        """Torque-on with a servo outside [min_deg, max_deg] holds it where it is instead
        of refusing (for ``handrig calibrate servos``, where the zero is being found)."""

        # -- present-state read
        self.read_fields: ReadFields = read_fields
        self._read_addr, self._read_len = _READ_SPANS[read_fields]
        # Each read asks for the servos in another order (up to ORDERS of them, rig
        # order first): a reply arriving after its read gave up names the servos in
        # its own order and is recognised as late instead of being taken for a later
        # read's (Protocol 2.0 has no sequence numbers). Only a reply a multiple of
        # len(self._orders) reads late could pass.
        self._orders: list[tuple[np.ndarray, tuple[int, ...], bytes, bytes]] = []
        self._order_ids_np: list[np.ndarray] = []  # each order's IDs, for the kernel
        seen_orders: set[bytes] = set()
        rng = np.random.default_rng(0)
        candidates = [np.roll(np.arange(n), -r) for r in range(n)]
        for attempt in range(4 * ORDERS):
            if len(self._orders) >= ORDERS:
                break
            idx = candidates[attempt] if attempt < n else rng.permutation(n)
            ids = tuple(self.ids[int(i)] for i in idx)
            if bytes(ids) in seen_orders:
                continue
            seen_orders.add(bytes(ids))
            self._orders.append((idx, ids, bytes(ids), build_instruction(
                BROADCAST_ID, INST_FAST_SYNC_READ,
                u16(self._read_addr) + u16(self._read_len) + bytes(ids),
            )))
            self._order_ids_np.append(np.array(ids, np.uint8))
        self._order_of = {id(o[0]): k for k, o in enumerate(self._orders)}
        self._fsr_full = self._orders[0][3]
        self._reply_len_full = 8 + (self._read_len + 4) * n
        # a whole read's next state, allocated while the reply is on the wire
        self._next_state: ServoState | None = None
        self._next_out: tuple[np.ndarray, np.ndarray] | None = None
        self._whole_at = 0.0  # when the last whole read was decoded
        self._skip_run = 0  # reads in a row not sent for lack of wire time
        if reply_timeout_s is None:
            wire = wire_time_s(len(self._fsr_full) + self._reply_len_full, self.baud)
            reply_timeout_s = 2.0 * wire + 0.002
        self.reply_timeout_s = float(reply_timeout_s)
        # a temperature Fast Sync Read: request 14 + N bytes, reply 8 + 5N
        self._temperature_wire_s = wire_time_s(22 + 6 * n, self.baud) + 0.0005
        # a read's default budget is never shorter than one reply on the wire plus slack
        self._min_read_budget_s = 1.5 * wire_time_s(
            len(self._fsr_full) + self._reply_len_full, self.baud
        ) + 0.001
        # a reply that stops flowing this long is cut short (USB adapters deliver in
        # chunks at most a latency-timer period apart: 1 ms when set as commissioning asks)
        self.reply_gap_s = (
            float(reply_gap_s) if reply_gap_s is not None
            else 0.0015 + wire_time_s(32, self.baud)
        )
        self.spin_s = float(spin_s)
        self._byte_s = BITS_PER_BYTE / self.baud
        self._bus_free_at = -np.inf  # when the wire is expected to be quiet again
        self._pending_tx = b""  # a goal Sync Write to send with the next request
        self._whole = False  # this read got every servo at once, no Alert bit raised
        self._last_tx_s = -np.inf  # when the host last put bytes on the bus
        self._watchdog_gap_s = (
            WATCHDOG_GAP_FRACTION * rig.bus.watchdog_ms / 1000.0 if rig.bus.watchdog_ms
            else np.inf
        )
        # when a reply failed (None: none did since the last request): the line must be
        # quiet for reply_gap_s after that, and after any byte since, before a request
        self._dirty_at: float | None = None
        self.use_fast_sync_read = True
        self._fast_fail_run = 0
        self._all_indices = self._orders[0][0]
        self._valid = [False] * n
        self._ids_bytes = bytes(self.ids)

        # -- latest readings (rig order); rows of one array for kernels.fast_sync_whole
        self._latest = np.full((5, n), np.nan)
        self._pos_deg, self._vel_dps, self._cur_ma, self._temp_c, self._read_time = self._latest
        self._read_time[:] = -np.inf
        self._status_err = np.zeros(n, np.uint8)
        self._hw_err = np.zeros(n, np.uint8)
        self._fresh = np.zeros(n, bool)
        self._stale_run = np.zeros(n, np.int64)
        self._stats = BusStats(n)

        self.commissioning: list[str] = []  # what connect() found and did, one line each
        self.models: dict[int, int] = {}
        self.firmware: dict[int, int] = {}
        self._connected = False
        self._torque_on = False

    # ------------------------------------------------------------------ properties
    @property
    def joint_names(self) -> tuple[str, ...]:
        return self._names

    @property
    def stats(self) -> BusStats:
        return self._stats

    @property
    def torque_enabled(self) -> bool:
        return self._torque_on

    @property
    def last_goals_deg(self) -> np.ndarray:
        """The goals last sent, after clamping (NaN before the first write)."""
        return self._last_goal_deg.copy()

    def describe(self, index: int) -> str:
        """``"servo 7 (riRingPIPy)"`` for the servo at rig index ``index``."""
        return f"servo {self.ids[index]} ({self._names[index]})"

    def _where(self) -> str:
        return f"on {self.port} at {self.baud} baud"

    # ------------------------------------------------------------------ low level
    def _next_status(self, deadline: float) -> StatusPacket | None:
        """The next status packet that passes its CRC before ``deadline``. Packets failing
        it are counted and skipped; none in time counts a timeout, marks the line dirty
        (a late reply may still arrive) and returns None."""
        while True:
            raw = self._transport.read_packet(deadline)
            if raw is None:
                self._stats.timeouts += 1
                self._dirty_at = self.clock.now()
                return None
            try:
                return parse_status(raw)
            except ProtocolError:
                self._stats.crc_errors += 1

    def _transact(
        self, packet: bytes, servo_id: int, *, timeout_s: float = COMMAND_TIMEOUT_S,
        attempts: int = COMMAND_ATTEMPTS, n_params: int | None = None,
    ) -> StatusPacket | None:
        """Send ``packet`` and return ``servo_id``'s status reply, or None after ``attempts``.

        ``n_params``: the reply's parameter count when it succeeds (a status with
        another count and no error is a reply to something else, e.g. late).
        """
        t = self._transport
        for attempt in range(attempts):
            if attempt:
                self._stats.retries += 1
            self._quiet_line()
            t.write(packet)
            deadline = self.clock.now() + timeout_s
            while (status := self._next_status(deadline)) is not None:
                if status.servo_id != servo_id or (
                    n_params is not None and not status.error & 0x7F
                    and len(status.params) != n_params
                ):
                    self._stats.malformed += 1
                    continue
                return status
        return None

    def _quiet_line(self, deadline_s: float | None = None) -> None:
        """Before a request: drop old input; after a failed reply, wait for the line to
        have been quiet ``reply_gap_s`` since the failure (a late reply still on the wire
        would collide with the request), at most ``reply_timeout_s`` and not past
        ``deadline_s``."""
        if self._dirty_at is not None:
            since, self._dirty_at = self._dirty_at, None
            most = self.reply_timeout_s
            if deadline_s is not None:
                most = min(most, deadline_s - self.clock.now())
            self._transport.wait_quiet(self.reply_gap_s, max(0.0, most), since_s=since)
        else:
            self._transport.discard_input()

    def _command(
        self, index: int, instruction: int, params: bytes, what: str, n_params: int = 0
    ) -> StatusPacket:
        """One instruction to servo ``index`` that must be answered without an error number."""
        sid = self.ids[index]
        status = self._transact(
            build_instruction(sid, instruction, params), sid, n_params=n_params
        )
        if status is None:
            raise DeviceTimeoutError(
                f"{self.describe(index)} did not answer {what} {self._where()} after "
                f"{COMMAND_ATTEMPTS} attempts: check power, cable and ID"
            )
        if status.error & 0x7F:
            raise ServoFault(
                f"{self.describe(index)} refused {what}: {describe_status_error(status.error)}",
                servo_id=sid, bits=status.error,
            )
        if status.error & ERR_ALERT:
            self._hw_alert(index)
        return status

    def read_register(self, index: int, reg: Reg) -> int:
        """Read one control-table item of servo ``index`` (rig order)."""
        status = self._command(
            index, INST_READ, u16(reg.address) + u16(reg.size), f"a read of {reg.name}",
            n_params=reg.size,
        )
        if len(status.params) < reg.size:
            self._stats.malformed += 1
            raise ProtocolError(
                f"{self.describe(index)} sent {len(status.params)} bytes for {reg.name} "
                f"({reg.size} expected) {self._where()}"
            )
        return reg.decode(status.params)

    def write_register(self, index: int, reg: Reg, value: int) -> None:
        """Write one control-table item of servo ``index`` and check the reply."""
        self._command(
            index, INST_WRITE, u16(reg.address) + reg.encode(value),
            f"a write of {reg.name} = {value}",
        )

    def _sync_write(self, reg: Reg, values: list[int]) -> None:
        params = u16(reg.address) + u16(reg.size) + b"".join(
            bytes((sid,)) + reg.encode(v) for sid, v in zip(self.ids, values, strict=True)
        )
        self._send_request(build_instruction(BROADCAST_ID, INST_SYNC_WRITE, params))

    def _hw_alert(self, index: int) -> None:
        """Remember that servo ``index`` raised its Alert bit (handled after the read)."""
        self._status_err[index] |= ERR_ALERT

    # ------------------------------------------------------------------ connect
    def connect(self) -> None:
        """Open the port and commission every servo.

        Pings each configured servo and checks its model; sets Return Delay Time 0,
        position mode and Status Return Level 2 (torque off while doing so); clears
        the Bus Watchdog; checks or sets the USB latency timer; probes Fast Sync
        Read. Raises DeviceError listing every servo that is missing or wrong.
        """
        with self._lock:
            if self._connected:
                return
            self._transport.open()
            try:
                self._commission()
            except BaseException:
                self._transport.close()
                raise
            self._connected = True

    def _commission(self) -> None:
        notes = self.commissioning
        notes.clear()
        notes.append(self._transport.latency_timer().note)
        problems: list[str] = []
        missing = 0
        # traffic of an earlier session (replies still queued) must not pass for answers
        self._transport.wait_quiet(0.02, 0.5)
        for i, sid in enumerate(self.ids):
            status = self._transact(build_instruction(sid, INST_PING), sid, n_params=3)
            if status is None or len(status.params) < 3:
                missing += 1
                problems.append(
                    f"{self.describe(i)} did not answer {self._where()}: check power and ID"
                )
                continue
            model = status.params[0] | status.params[1] << 8
            self.models[sid] = model
            self.firmware[sid] = status.params[2]
            want = self._expected_models[i]
            if model != want:
                names = {v: k for k, v in MODEL_NUMBERS.items()}
                problems.append(
                    f"{self.describe(i)} is model {model} ({names.get(model, 'unknown')}), "
                    f"the rig says {self.rig.servos[i].model} ({want}): fix config/rig.toml "
                    "or the servo"
                )
        if problems:
            if missing == self._n:
                problems.append(
                    f"no configured servo answered: check the power supply, the adapter and "
                    f"that the servos are set to {self.baud} baud (register 8)"
                )
            elif missing:
                found = sorted(self._broadcast_ping())
                problems.append(f"IDs answering a broadcast ping {self._where()}: "
                                f"{found or 'none'}")
                flaky = [sid for sid in self.ids if sid in found and sid not in self.models]
                if flaky:
                    problems.append(
                        f"servo(s) {flaky} answered the broadcast ping but not "
                        f"{COMMAND_ATTEMPTS} pings of their own: the bus is unreliable "
                        "(cable, termination, power, or a baud rate the adapter barely holds)"
                    )
            raise DeviceError("; ".join(problems))
        notes.append(f"{self._n} servos answered {self._where()} with the expected models")

        for i in range(self._n):
            self._ensure_status_return_level(i)
            self.write_register(i, Reg.TORQUE_ENABLE, 0)
            for reg, want, why in (
                (Reg.RETURN_DELAY_TIME, 0, "return delay 0 us"),
                (Reg.OPERATING_MODE, OPERATING_MODE_POSITION, "position control mode"),
            ):
                value = self.read_register(i, reg)
                if value != want:
                    self.write_register(i, reg, want)
                    notes.append(f"{self.describe(i)}: {reg.name} {value} -> {want} ({why})")
            self.write_register(i, Reg.BUS_WATCHDOG, 0)
            hw = self.read_register(i, Reg.HARDWARE_ERROR_STATUS)
            if hw:
                self._hw_err[i] = hw
                self._stats.hardware_errors[i] += 1
                self._on_hardware_error(i, hw)
        notes.append("return delay 0, position mode, status level 2, watchdog cleared: done")

        if not any(
            self._fast_sync_read(self._all_indices, self.clock.now() + COMMAND_TIMEOUT_S)
            for _ in range(COMMAND_ATTEMPTS)
        ):
            self._switch_to_sync_read(
                f"no valid Fast Sync Read reply in {COMMAND_ATTEMPTS} attempts at connect"
            )
        notes.append(
            "present state by " + ("Fast Sync Read" if self.use_fast_sync_read else "Sync Read")
        )
        self._read_every_servo("finish commissioning")

    def _ensure_status_return_level(self, index: int) -> None:
        """Status Return Level 2 (a status for every instruction), which the driver needs.

        At level 1 a write gets no reply and at level 0 neither does a read, so the
        item is written without waiting for a reply, then read back.
        """
        reg = Reg.STATUS_RETURN_LEVEL
        try:
            level: int | None = self.read_register(index, reg)
        except DeviceTimeoutError:
            level = None  # level 0: only pings are answered
        if level == STATUS_RETURN_ALL:
            return
        sid = self.ids[index]
        self._last_tx_s = self.clock.now()
        self._transport.write(build_instruction(
            sid, INST_WRITE, u16(reg.address) + reg.encode(STATUS_RETURN_ALL)
        ))
        self.clock.sleep(COMMAND_TIMEOUT_S / 5)
        self._transport.discard_input()
        try:
            now = self.read_register(index, reg)
        except DeviceTimeoutError:
            now = None
        if now != STATUS_RETURN_ALL:
            raise DeviceError(
                f"{self.describe(index)} answers ping but keeps Status Return Level {now} "
                f"{self._where()}: set it to 2 (e.g. with DYNAMIXEL Wizard)"
            )
        was = "0 (reads unanswered)" if level is None else str(level)
        self.commissioning.append(
            f"{self.describe(index)}: STATUS_RETURN_LEVEL {was} -> 2 (status for every "
            "instruction)"
        )

    def _broadcast_ping(self, wait_s: float = 0.1) -> dict[int, int]:
        t = self._transport
        self._quiet_line()
        t.write(build_instruction(BROADCAST_ID, INST_PING))
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

    def _switch_to_sync_read(self, why: str) -> None:
        if self.use_fast_sync_read:
            self.use_fast_sync_read = False
            self._stats.fallbacks += 1
            msg = f"falling back from Fast Sync Read to Sync Read {self._where()}: {why}"
            self.commissioning.append(msg)
            log.warning(msg)

    # ------------------------------------------------------------------ goals
    def write_goals_deg(self, goals_deg: np.ndarray) -> int:
        """Send one goal per servo (joint degrees, rig order) in one Sync Write.

        Each goal is clamped to the servo's ``[min_deg, max_deg]``; a non-finite
        goal is replaced by the last goal sent (or the servo's zero clamped into its
        limits). Returns how many goals were changed that way (also counted in
        ``stats.clamps``). No reply is expected.
        """
        with self._lock:
            self._rearm_after_silence()
            clamped = self._clamp_goals(goals_deg)
            self._send_built_goals()
        return clamped

    def write_and_read(
        self, goals_deg: np.ndarray, deadline_s: float | None = None
    ) -> tuple[int, ServoState]:
        """``write_goals_deg`` then ``read_state``, both requests in one write to the port.

        The same bytes go on the wire in the same order; the host saves a system
        call and the adapter (or emulator) one wake-up. Returns (clamped, state).
        """
        with self._lock:
            self._rearm_after_silence()
            clamped = self._clamp_goals(goals_deg)
            self._pending_tx = self._sw_packet.tobytes()
            self._last_goal_deg[:] = self._goal_deg
            self._stats.writes += 1
            try:
                state = self.read_state(deadline_s)
            finally:
                if self._pending_tx:  # not sent by the read: send it on its own
                    self._send_request(b"")
        return clamped, state

    def _rearm_after_silence(self) -> None:
        """Before goals: if the host was silent longer than the Bus Watchdog (a stalled
        process, a long pause), the servos' watchdogs have tripped and they refuse goal
        writes until it is cleared; clear and re-arm it by broadcast first (two Sync
        Writes, no replies), counted in ``stats.watchdog_gaps``. Housekeeping reads
        the watchdogs back later."""
        watchdog_ms = self.rig.bus.watchdog_ms
        if not self._torque_on or not watchdog_ms:
            return
        silent_s = self.clock.now() - self._last_tx_s
        if silent_s < self._watchdog_gap_s:
            return
        self._stats.watchdog_gaps += 1
        log.warning("the bus was silent for %.0f ms (Bus Watchdog %d ms): re-arming the "
                    "watchdogs before the next goals", silent_s * 1e3, watchdog_ms)
        self._sync_write(Reg.BUS_WATCHDOG, [0] * self._n)
        self._sync_write(Reg.BUS_WATCHDOG, [watchdog_ms // BUS_WATCHDOG_UNIT_MS] * self._n)

    def _clamp_goals(self, goals_deg: np.ndarray) -> int:
        """Goals clamped into ``self._goal_deg`` and the goal Sync Write built from them
        (``self._sw_packet``); returns (and counts) how many goals changed."""
        clamped = self._clamp_into(goals_deg, self._goal_deg, self._sw_packet)
        self._stats.clamps += clamped
        return clamped

    def _clamp_into(self, goals_deg: np.ndarray, goal: np.ndarray, packet: np.ndarray) -> int:
        """``goals_deg`` clamped to the limits into ``goal`` (a non-finite goal becomes the
        last goal sent, or the hold position), and their ticks into the Sync Write
        ``packet`` with its CRC; returns how many changed. No counters. One compiled
        loop (handrig.kernels)."""
        g = np.ascontiguousarray(goals_deg, dtype=np.float64)
        if g.shape != (self._n,):
            raise ValueError(f"goals_deg must have shape ({self._n},), got {g.shape}")
        return int(kernels.goal_packet(
            g, self._min_deg, self._max_deg, self._last_goal_deg, self._hold_deg,
            self._ticks_per_deg, self._zero_ticks, goal, packet))

    def _send_request(self, packet: bytes | memoryview) -> None:
        """Write ``packet`` after any goal Sync Write held back by ``write_and_read``."""
        data = self._pending_tx + bytes(packet) if self._pending_tx else packet
        self._pending_tx = b""
        self._transport.write(data)
        now = self.clock.now()
        self._last_tx_s = now
        self._bus_free_at = max(now, self._bus_free_at) + len(data) * self._byte_s

    def rehearse_write(self, goals_deg: np.ndarray) -> None:
        """Build the goal Sync Write for ``goals_deg`` without sending it, counting or
        remembering anything: the loop calls it shortly before a deadline so the write
        path is warm in the CPU's caches when the real goals come (see handrig.rig)."""
        with self._lock:
            self._clamp_into(goals_deg, self._rehearsal_goal, self._rehearsal_packet)

    def _send_goals(self, goal_deg: np.ndarray) -> None:
        """Send ``goal_deg`` (already within limits) as the goal Sync Write."""
        with self._lock:
            self._clamp_into(goal_deg, self._goal_deg, self._sw_packet)
            self._send_built_goals()

    def _send_built_goals(self) -> None:
        """Send the Sync Write :meth:`_clamp_goals` built for ``self._goal_deg``."""
        # Ticks in 0..4095 and IDs <= 252 never form FF FF FD: no stuffing needed.
        self._send_request(self._sw_view)
        self._stats.writes += 1
        self._last_goal_deg[:] = self._goal_deg

    # ------------------------------------------------------------------ present state
    def read_state(self, deadline_s: float | None = None) -> ServoState:
        """Read present state (Fast Sync Read, or Sync Read after a fallback).

        ``deadline_s`` is a time on the bus clock by which the read must end
        (default: ``fault_policy.read_budget_s``, at least 1.5 times the reply's
        wire time plus 1 ms, from when the wire is free of the last goal write);
        failed servos are retried up to ``fault_policy.read_retries`` times while
        time remains.
        Servos without a valid reply are marked stale, never passed off as fresh.
        A read (or retry) whose request and reply could not both be on the wire
        before the deadline is not sent: on a half-duplex bus its reply would still
        be arriving when the caller's next goals go out. Its servos are marked stale
        (``stats.skipped_reads``), not counted as a servo's stale run;
        ``max_stale_reads`` skipped reads in a row raise DeviceTimeoutError (the
        caller's deadlines never leave the wire time a read needs).
        A servo raising its Alert bit is handled per policy (reboot or
        ServoFault); a servo stale ``max_stale_reads`` times in a row raises
        DeviceTimeoutError naming it.
        """
        with self._lock:
            now = self.clock.now()
            if deadline_s is None:
                # from when the wire is free of the goal Sync Write just sent
                deadline_s = self._request_start(now) + max(
                    self.policy.read_budget_s, self._min_read_budget_s
                )
            elif self._request_start(now) + self._read_wire_s(self._n) > deadline_s:
                self._stats.skipped_reads += 1
                self._skip_run += 1
                if self._skip_run >= self.policy.max_stale_reads:
                    raise DeviceTimeoutError(
                        f"no read of the servos fitted its deadline {self._skip_run} times "
                        f"in a row {self._where()}: one takes "
                        f"{self._read_wire_s(self._n) * 1e3:.2f} ms of wire, the caller "
                        f"allowed {(deadline_s - now) * 1e3:.2f} ms; raise the baud rate, "
                        "read fewer fields or read less often")
                return self._unread_state(now)
            self._skip_run = 0
            self._stats.reads += 1
            fresh = self._fresh
            fresh[:] = False
            self._status_err[:] = 0
            self._hw_err[:] = 0
            pending = self._orders[self._stats.reads % len(self._orders)][0]
            self._whole = False
            for attempt in range(self.policy.read_retries + 1):
                if attempt:
                    start = self._request_start(self.clock.now())
                    if start + self._read_wire_s(len(pending)) > deadline_s:
                        break
                    self._stats.retries += 1
                self._read_attempt(pending, deadline_s)
                if self._whole:
                    if self._stats.reads < self._next_temperature_read or not (
                            self.temperature_every):
                        # kernels.fast_sync_whole did the rest of this method's work
                        state = self._next_state
                        assert state is not None
                        self._next_state = self._next_out = None
                        state.timestamp_s = self._whole_at
                        return state
                    break
                if fresh.all():
                    break
                # A Fast Sync Read reply stops at the first servo that does not answer:
                # ask the rest (in the order just asked) first, the one where it stopped last.
                pending = np.roll(pending[~fresh[pending]], -1)
            now = self.clock.now()
            stale = ~fresh
            all_fresh = self._whole or bool(fresh.all())
            if all_fresh:
                # every reply is in, so the wire is quiet (an emulator without wire
                # timing answers faster than the wire: the estimate must not run ahead)
                self._bus_free_at = min(self._bus_free_at, now)
                self._stale_run[:] = 0
                self._read_time[:] = now
            else:
                self._stale_run[stale] += 1
                self._stale_run[fresh] = 0
                self._stats.stale_readings[stale] += 1
                self._read_time[fresh] = now
            if not self._whole and self._status_err.any():
                for i in np.flatnonzero(self._status_err & ERR_ALERT):
                    self._hardware_alert(int(i))
            if (
                self.temperature_every
                and self._stats.reads >= self._next_temperature_read
                and deadline_s - self.clock.now() > self._temperature_wire_s
            ):
                self._next_temperature_read = self._stats.reads + self.temperature_every
                self._housekeeping(deadline_s)
            worst = 0 if all_fresh else int(self._stale_run.argmax())
            if not all_fresh and self._stale_run[worst] >= self.policy.max_stale_reads:
                raise DeviceTimeoutError(
                    f"{self.describe(worst)} gave no valid reading in "
                    f"{int(self._stale_run[worst])} reads in a row {self._where()} "
                    f"({self._stats.summary()}): check its cable, power and ID"
                )
            return self._snapshot(now, stale, self._hw_err.copy())

    def _request_start(self, now: float) -> float:
        """When a request written now would start on the wire: after what is still on
        it, a goal Sync Write held back by ``write_and_read``, and the wait for a
        quiet line after a failed reply (:meth:`_quiet_line`)."""
        start = max(now, self._bus_free_at) + len(self._pending_tx) * self._byte_s
        if self._dirty_at is None:
            return start
        quiet_from = max(self._dirty_at, self._transport.last_rx_s)
        return max(start, quiet_from + self.reply_gap_s)

    def _read_wire_s(self, n: int) -> float:
        """Wire time of a present-state read of ``n`` servos: the request and every reply."""
        if self.use_fast_sync_read:
            n_bytes = 14 + n + 8 + (self._read_len + 4) * n
        else:
            n_bytes = 14 + n + (11 + self._read_len) * n
        return n_bytes * self._byte_s

    def _unread_state(self, now: float) -> ServoState:
        """The state of a read that was not sent: every servo stale, its last reading."""
        return self._snapshot(now, np.ones(self._n, bool), np.zeros(self._n, np.uint8))

    def _snapshot(self, now: float, stale: np.ndarray, hardware_errors: np.ndarray) -> ServoState:
        """A state of copies of the latest readings and counters, marked ``stale``."""
        return ServoState(
            positions_deg=self._pos_deg.copy(),
            velocities_dps=self._vel_dps.copy(),
            currents_ma=self._cur_ma.copy(),
            temperatures_c=self._temp_c.copy(),
            status_errors=self._status_err.copy(),
            hardware_errors=hardware_errors,
            stale=stale,
            age_s=now - self._read_time,
            timestamp_s=now,
            stats=self._stats.copy(),
        )

    def _read_attempt(self, indices: np.ndarray, deadline_s: float) -> bool:
        """One read of ``indices``; updates readings of servos that answered validly."""
        deadline = min(deadline_s, self._reply_deadline())
        if self.use_fast_sync_read:
            got = self._fast_sync_read(indices, deadline)
            if got:
                self._fast_fail_run = 0
            else:
                self._fast_fail_run += 1
                if self._fast_fail_run >= self.policy.fast_failures_before_fallback:
                    self._fast_fail_run = 0
                    deadline = min(deadline_s, self._reply_deadline())
                    if self._sync_read(indices, deadline):
                        self._switch_to_sync_read(
                            f"{self.policy.fast_failures_before_fallback} Fast Sync Reads "
                            "failed in a row while Sync Read works"
                        )
                        return True
            return got
        return self._sync_read(indices, deadline)

    def _reply_deadline(self) -> float:
        """When a reply to a request sent now is overdue (the wire may still be busy)."""
        return max(self.clock.now(), self._bus_free_at) + self.reply_timeout_s

    def _fast_sync_read(self, indices: np.ndarray, deadline: float) -> bool:
        t = self._transport
        n_req = len(indices)
        order = self._order_of.get(id(indices))  # every servo, in a precomputed order
        if order is not None:
            _, ids, ids_bytes, packet = self._orders[order]
        else:
            ids = tuple(self.ids[int(i)] for i in indices)
            ids_bytes = bytes(ids)
            packet = build_instruction(
                BROADCAST_ID, INST_FAST_SYNC_READ,
                u16(self._read_addr) + u16(self._read_len) + ids_bytes,
            )
        block = self._read_len + 4
        expected = 8 + block * n_req
        self._quiet_line(deadline)
        self._send_request(packet)
        if order is not None:
            self._prepare_state()  # while the request and the reply are on the wire
        # the reply cannot end before the wire has carried the request and the reply
        spin_from = None
        spin_until = np.inf
        if self.spin_s > 0:
            arrival = self._bus_free_at + expected * self._byte_s
            spin_from = arrival - self.spin_s
            spin_until = arrival + REPLY_POLL_AFTER_S
        head = t.read_exact(7, deadline, spin_from, spin_until_s=spin_until)
        if len(head) < 7:
            self._stats.timeouts += 1
            self._dirty_at = self.clock.now()
            return False
        if head[:4] != HEADER:
            self._stats.malformed += 1
            self._dirty_at = self.clock.now()
            return False
        total = packet_length(head)
        if head[4] != BROADCAST_ID:
            # a single servo's status: an error report (e.g. instruction error) or a wrong reply
            rest = t.read_exact(total - 7, deadline) if total <= 1024 else b""
            try:
                status = parse_status(head + rest)
            except ProtocolError:
                self._stats.crc_errors += 1
                return False
            self._stats.malformed += 1
            if status.error & 0x7F == 2:  # instruction error: Fast Sync Read unsupported
                self._switch_to_sync_read(
                    f"servo {status.servo_id} answered 'instruction error' to Fast Sync Read"
                )
            return False
        if total != expected:
            self._stats.malformed += 1
        raw = head + t.read_exact(
            min(total, expected) - 7, deadline, spin_from, self.reply_gap_s, spin_until
        )
        if order is not None and self._take_whole(raw, indices, order):
            return True
        # A reply whose blocks name other servos, or ours in another order, is not the
        # reply to this request: an intact one is a late reply to an earlier read
        # (dropped; the one asked for may follow), anything else is rejected whole.
        late = False
        for _ in range(4):
            m = min(n_req, (len(raw) - 8) // block)
            named = raw[9 : 8 + m * block : block]
            if m <= 0 or named == ids_bytes[:m]:
                break
            if (
                len(raw) == expected and sorted(named) == sorted(ids_bytes)
                and fast_sync_intact(raw, named, self._read_len)
            ):
                self._stats.late_replies += 1
                raw = self._read_reply(expected, deadline)
                late = True
                continue
            self._stats.malformed += 1
            self._dirty_at = self.clock.now()
            return False
        else:
            return False
        # an intact reply after a late one was dropped: every servo at once
        if late and order is not None and self._take_whole(raw, indices, order):
            assert self._next_state is not None
            self._next_state.stats = self._stats.copy()  # the late reply counted
            return True
        if len(raw) < expected:
            self._stats.timeouts += 1
            self._dirty_at = self.clock.now()
        m = min(n_req, (len(raw) - 8) // block)  # complete blocks received
        if m <= 0:
            return False
        valid = self._valid
        fast_sync_valid(raw, ids, self._read_len, valid)
        ok = np.array(valid[:m], dtype=bool)
        n_ok = int(ok.sum())
        if n_ok < m:
            self._stats.crc_errors += m - n_ok  # a bad CRC or a block naming the wrong servo
        blocks = np.frombuffer(raw, np.uint8, count=m * block, offset=8).reshape(m, block)
        refused = ok & (blocks[:, 0] & 0x7F != 0)
        if refused.any():
            # an error number (range, access, ...): its data bytes are filler, not a reading
            self._stats.status_errors += int(refused.sum())
            self._status_err[indices[:m][refused]] = blocks[refused, 0]
            ok &= ~refused
            n_ok = int(ok.sum())
        if n_ok == 0:
            return False
        target = indices[:m][ok]
        self._status_err[target] = blocks[ok, 0]
        self._decode(blocks[ok, 2 : 2 + self._read_len], target)
        self._fresh[target] = True
        return True

    def _prepare_state(self) -> None:
        """Allocate the state a whole read returns (arrays and counters), so that the
        work left once the reply is in is the one compiled pass of :meth:`_take_whole`."""
        n = self._n
        out = np.empty((5, n))
        out_u8 = np.empty((3, n), np.uint8)
        self._next_out = (out, out_u8)
        self._next_state = ServoState(
            positions_deg=out[0], velocities_dps=out[1], currents_ma=out[2],
            temperatures_c=out[3], status_errors=out_u8[0], hardware_errors=out_u8[1],
            stale=out_u8[2].view(np.bool_), age_s=out[4], timestamp_s=np.nan,
            stats=self._stats.copy(),  # what they will be if this read is whole
        )

    def _take_whole(self, raw: bytes, indices: np.ndarray, order: int) -> bool:
        """Decode a reply to a request for every servo (order ``order``) if intact as a
        whole and no servo reports an error number (True; ``self._whole`` when no
        servo raises its Alert bit either, and then ``self._next_state`` is the
        read's state); False with nothing changed otherwise."""
        assert self._next_out is not None
        now = self.clock.now()
        alerts = kernels.fast_sync_whole(
            np.frombuffer(raw, np.uint8), self._read_len, indices, self._order_ids_np[order],
            self._scale, self._latest, self._status_err, self._stale_run, self._fresh, now,
            *self._next_out)
        if alerts < 0:
            return False
        self._whole = alerts == 0  # every servo fresh, none raising its Alert bit
        self._whole_at = now
        self._bus_free_at = min(self._bus_free_at, now)  # the reply is in: the wire is quiet
        return True

    def _sync_read(self, indices: np.ndarray, deadline: float) -> bool:
        ids = [self.ids[int(i)] for i in indices]
        self._quiet_line(deadline)
        self._send_request(build_instruction(
            BROADCAST_ID, INST_SYNC_READ,
            u16(self._read_addr) + u16(self._read_len) + bytes(ids),
        ))
        want = {sid: int(i) for sid, i in zip(ids, indices, strict=True)}
        rows = np.zeros((len(ids), self._read_len), np.uint8)
        got: list[int] = []
        while len(got) < len(ids):
            status = self._next_status(deadline)
            if status is None:
                break
            index = want.pop(status.servo_id, None)
            if index is not None and status.error & 0x7F:
                self._stats.status_errors += 1
                self._status_err[index] = status.error
                continue
            if index is None or len(status.params) < self._read_len:
                self._stats.malformed += 1
                continue
            rows[len(got)] = np.frombuffer(status.params[: self._read_len], np.uint8)
            self._status_err[index] = status.error
            got.append(index)
        if not got:
            return False
        target = np.array(got, dtype=np.intp)
        self._decode(rows[: len(got)], target)
        self._fresh[target] = True
        return True

    def _decode(self, data: np.ndarray, target: np.ndarray) -> None:
        """Turn raw little-endian rows (k, read_len) into readings for rig indices ``target``."""
        rows = np.ascontiguousarray(data)
        if self.read_fields == "position":
            pos = rows.view("<i4")[:, 0]
        else:
            cur = rows[:, 0:2].copy().view("<i2")[:, 0]
            vel = rows[:, 2:6].copy().view("<i4")[:, 0]
            pos = rows[:, 6:10].copy().view("<i4")[:, 0]
            self._cur_ma[target] = cur * self._current_ma_per_unit[target]
            self._vel_dps[target] = vel * self._dps_per_unit[target]
        self._pos_deg[target] = (pos - self._zero_ticks[target]) / self._ticks_per_deg[target]

    def _read_reply(self, n: int, deadline: float) -> bytes:
        """Up to ``n`` bytes of a reply: its start may take until ``deadline`` (the wire
        can still be busy with earlier packets); once it has started, a gap of
        ``reply_gap_s`` ends it. The gap must not count from the request: measured
        in ``handrig demo`` (1 Mbps, 20 servos), a Bus Watchdog read sent while a
        Sync Write was still on the wire gave up after 2.0-2.3 ms with nothing,
        its reply due 2.4 ms after the request."""
        t = self._transport
        head = t.read_exact(min(n, 7), deadline)
        if len(head) < min(n, 7):
            return head
        return head + t.read_exact(n - len(head), deadline, gap_s=self.reply_gap_s)

    def _read_byte_register(self, reg: Reg, deadline_s: float) -> list[int | None]:
        """A one-byte item of every servo (Fast Sync Read, or Sync Read after a fallback);
        None for a servo without a valid reply."""
        deadline = min(deadline_s, self._reply_deadline())
        t = self._transport
        out: list[int | None] = [None] * self._n
        self._quiet_line(deadline)
        params = u16(reg.address) + u16(1) + self._ids_bytes
        if self.use_fast_sync_read:
            self._send_request(build_instruction(BROADCAST_ID, INST_FAST_SYNC_READ, params))
            raw = self._read_reply(8 + 5 * self._n, deadline)
            valid = self._valid
            fast_sync_valid(raw, self.ids, 1, valid)
            for i in range(self._n):
                if valid[i] and not raw[8 + 5 * i] & 0x7F:
                    out[i] = reg.decode(raw[8 + 5 * i + 2 : 8 + 5 * i + 3])
        else:
            self._send_request(build_instruction(BROADCAST_ID, INST_SYNC_READ, params))
            for _ in range(self._n):
                packet = t.read_packet(deadline)
                if packet is None:
                    break
                try:
                    status = parse_status(packet)
                except ProtocolError:
                    self._stats.crc_errors += 1
                    continue
                index = self._index_of_id.get(status.servo_id)
                if index is not None and status.params and not status.error & 0x7F:
                    out[index] = reg.decode(status.params[:1])
        if None in out:
            self._stats.timeouts += 1
            self._dirty_at = self.clock.now()
        return out

    def _housekeeping(self, deadline_s: float) -> None:
        """With torque on, the Bus Watchdogs first (re-armed if one tripped), then the
        temperatures if the read's deadline leaves time for them."""
        if self._torque_on and self.rig.bus.watchdog_ms:
            watchdogs = self._read_byte_register(Reg.BUS_WATCHDOG, deadline_s)
            tripped = [i for i, v in enumerate(watchdogs) if v == BUS_WATCHDOG_TRIPPED]
            if tripped:
                self._stats.watchdog_trips += len(tripped)
                log.warning(
                    "Bus Watchdog tripped on %s (the bus was quiet for more than %d ms): "
                    "re-arming", ", ".join(self.describe(i) for i in tripped),
                    self.rig.bus.watchdog_ms,
                )
                self._arm_watchdog()
            if deadline_s - self.clock.now() <= self._temperature_wire_s:
                return
        for i, value in enumerate(self._read_byte_register(Reg.PRESENT_TEMPERATURE, deadline_s)):
            if value is not None:
                self._temp_c[i] = value

    def _read_every_servo(self, purpose: str) -> ServoState:
        """Read until every servo has given a valid reading (up to COMMAND_ATTEMPTS reads)."""
        seen = np.zeros(self._n, bool)
        for _ in range(COMMAND_ATTEMPTS):
            state = self.read_state(self.clock.now() + 4 * COMMAND_TIMEOUT_S)
            seen |= ~state.stale
            if seen.all():
                return state
        bad = [self.describe(int(i)) for i in np.flatnonzero(~seen)]
        raise DeviceError(
            f"cannot {purpose}: no valid present position from {', '.join(bad)} "
            f"{self._where()} in {COMMAND_ATTEMPTS} reads"
        )

    # ------------------------------------------------------------------ faults
    def _hardware_alert(self, index: int) -> None:
        try:
            bits = self.read_register(index, Reg.HARDWARE_ERROR_STATUS)
        except DeviceError as exc:
            log.warning("%s raised Alert but its Hardware Error Status is unreadable: %s",
                        self.describe(index), exc)
            return
        if not bits:
            return
        self._hw_err[index] = bits
        self._stats.hardware_errors[index] += 1
        self._on_hardware_error(index, bits)

    def _on_hardware_error(self, index: int, bits: int) -> None:
        what = (
            f"{self.describe(index)} hardware error 0x{bits:02x}: "
            f"{describe_hardware_error(bits)} {self._where()}"
        )
        if self.policy.on_hardware_error == "stop":
            raise ServoFault(f"{what}; policy: stop", servo_id=self.ids[index], bits=bits)
        if self._stats.reboots[index] >= self.policy.max_reboots:
            raise ServoFault(
                f"{what}; still there after {int(self._stats.reboots[index])} reboots: "
                "stopping (check the load, supply voltage and temperature)",
                servo_id=self.ids[index], bits=bits,
            )
        log.warning("%s; rebooting it", what)
        self.reboot(index)

    def reboot(self, index: int) -> None:
        """Reboot servo ``index`` (clears a hardware error), then restore its settings.

        If torque is on, the servo gets its last goal and torque back, and the Bus
        Watchdog is re-armed. Raises ServoFault if it does not come back within
        ``fault_policy.reboot_wait_s``.
        """
        with self._lock:
            sid = self.ids[index]
            # One attempt only: a lost status must not send a second reboot to a
            # servo that is already restarting (it would not answer that one either).
            status = self._transact(
                build_instruction(sid, INST_REBOOT), sid, attempts=1, n_params=0
            )
            if status is not None and status.error & 0x7F:
                raise ServoFault(
                    f"{self.describe(index)} refused a reboot: "
                    f"{describe_status_error(status.error)}", servo_id=sid, bits=status.error,
                )
            self._stats.reboots[index] += 1
            deadline = self.clock.now() + self.policy.reboot_wait_s
            while True:
                if self._torque_on and not np.isnan(self._last_goal_deg).any():
                    # keep the other servos' Bus Watchdogs fed while this one restarts
                    self._send_goals(self._last_goal_deg.copy())
                status = self._transact(
                    build_instruction(sid, INST_PING), sid, attempts=1, n_params=3
                )
                if status is not None:
                    break
                if self.clock.now() >= deadline:
                    raise ServoFault(
                        f"{self.describe(index)} did not come back within "
                        f"{self.policy.reboot_wait_s} s of a reboot {self._where()}",
                        servo_id=sid,
                    )
            remaining = self.read_register(index, Reg.HARDWARE_ERROR_STATUS)
            if remaining:
                log.warning("%s still reports hardware error 0x%02x after a reboot: %s",
                            self.describe(index), remaining, describe_hardware_error(remaining))
            self.write_register(index, Reg.RETURN_DELAY_TIME, 0)
            self.write_register(index, Reg.STATUS_RETURN_LEVEL, STATUS_RETURN_ALL)
            if self._torque_on:
                goal = self._last_goal_deg[index]
                if not np.isfinite(goal):
                    goal = self._hold_deg[index]
                ticks = int(np.clip(
                    round(self._zero_ticks[index] + goal * self._ticks_per_deg[index]),
                    0, POSITION_TICKS_MAX,
                ))
                self.write_register(index, Reg.GOAL_POSITION, ticks)
                self.write_register(index, Reg.TORQUE_ENABLE, 1)
                self._arm_watchdog()

    # ------------------------------------------------------------------ torque
    def torque(
        self, *, handle_signals: bool = True, on_signal: Callable[[str], None] | None = None
    ) -> _TorqueContext:
        """Context manager: torque on inside, off on every way out.

        On entry every servo gets its present position (clamped) as goal, then
        torque on, then the Bus Watchdog (``rig.bus.watchdog_ms``). On exit, normal
        or by exception, torque goes off on every servo and the watchdog is
        cleared. With ``handle_signals`` (main thread only) SIGTERM and SIGINT are
        caught while inside: the first calls ``on_signal(name)`` if given (e.g. a
        loop's graceful stop) or else raises SafetyStop (SIGTERM) /
        KeyboardInterrupt (SIGINT); a second signal raises at once; signals during
        the torque-off are ignored until it is done.
        """
        return _TorqueContext(self, handle_signals, on_signal)

    def _arm_watchdog(self) -> None:
        """Bus Watchdog to ``rig.bus.watchdog_ms`` on every servo at once, then checked.

        Broadcast Sync Writes reach every servo in one packet (servo by servo, the
        first ones armed could trip while a lossy bus delays the last); 0 first
        clears a tripped watchdog (-1). Servos not confirmed get checked writes.
        """
        units = self.rig.bus.watchdog_ms // BUS_WATCHDOG_UNIT_MS
        self._sync_write(Reg.BUS_WATCHDOG, [0] * self._n)
        if units:
            self._sync_write(Reg.BUS_WATCHDOG, [units] * self._n)
        for _ in range(COMMAND_ATTEMPTS):
            values = self._read_byte_register(
                Reg.BUS_WATCHDOG, self.clock.now() + COMMAND_TIMEOUT_S
            )
            if all(v is not None for v in values):
                break
        for i, value in enumerate(values):
            if value != units:
                if value is not None:  # answered with another value: set it explicitly
                    self.write_register(i, Reg.BUS_WATCHDOG, 0)
                    if units:
                        self.write_register(i, Reg.BUS_WATCHDOG, units)
                else:
                    self.write_register(i, Reg.BUS_WATCHDOG, units)

    def _enable_torque(self) -> None:
        with self._lock:
            if not self._connected:
                raise DeviceError(f"servo bus {self.port} is not connected: call connect()")
            # Profile Velocity is RAM: clear what an earlier run that died mid-approach left
            self._sync_write(Reg.PROFILE_VELOCITY, [0] * self._n)
            state = self._read_every_servo("enable torque")
            pos = state.positions_deg
            excess = np.maximum(self._min_deg - pos, pos - self._max_deg)
            outside = excess > TORQUE_ON_SLACK_DEG
            slow: list[int] = []  # servos given an approach speed, to be reset
            try:
                if outside.any() and self.hold_outside_limits:  # calibration: hold them
                    ticks = np.rint(self._zero_ticks + pos * self._ticks_per_deg)
                    for i in range(self._n):
                        tick = int(min(max(ticks[i], 0), POSITION_TICKS_MAX))
                        self.write_register(i, Reg.GOAL_POSITION, tick)
                    self._last_goal_deg[:] = pos  # a reboot re-sends where they were held
                else:
                    far = excess > MAX_APPROACH_DEG
                    if far.any():
                        bad = [f"{self.describe(int(i))} is at {pos[i]:.1f} deg, outside its "
                               f"limits [{self._min_deg[i]:g}, {self._max_deg[i]:g}]"
                               for i in np.flatnonzero(far)]
                        raise DeviceError(
                            f"cannot enable torque {self._where()}: {'; '.join(bad)}. That is "
                            f"more than {MAX_APPROACH_DEG:g} deg out (a wrong zero?): move the "
                            "joint into range by hand, or re-zero it with "
                            "`handrig calibrate servos`")
                    # a joint slightly out (a limp puppet on its stop) is brought in slowly
                    for j in np.flatnonzero(outside).tolist():
                        slow.append(j)
                        self.write_register(j, Reg.PROFILE_VELOCITY, self._approach_units[j])
                    # hold where they are, clamped into the limits
                    self.write_goals_deg(pos)
                self._torque_on = True
                for i in range(self._n):
                    self.write_register(i, Reg.TORQUE_ENABLE, 1)
                self._arm_watchdog()
                if slow:
                    self._finish_approach(np.array(slow), float(excess.max()))
            finally:
                for j in slow:  # best effort: never leave a servo speed-limited
                    with contextlib.suppress(DeviceError):
                        self.write_register(j, Reg.PROFILE_VELOCITY, 0)

    def _finish_approach(self, indices: np.ndarray, excess_deg: float) -> None:
        """Wait (bounded) for servos brought in slowly to reach their limits; a servo that
        does not get there in time (blocked, or not answering) is a DeviceError, so torque
        goes off rather than the servo finishing the move at full speed."""
        end = self.clock.now() + excess_deg / APPROACH_DPS * 2.0 + 0.5
        while True:
            self.write_goals_deg(self._last_goal_deg)  # keeps the watchdog fed
            state = self.read_state()
            pos = state.positions_deg[indices]
            inside = ~state.stale[indices] & (
                pos >= self._min_deg[indices] - TORQUE_ON_SLACK_DEG) & (
                pos <= self._max_deg[indices] + TORQUE_ON_SLACK_DEG)
            if inside.all():
                break
            if self.clock.now() >= end:
                late = [self.describe(int(i)) for i in indices[~inside]]
                raise DeviceError(
                    f"torque-on {self._where()}: {', '.join(late)} did not come into its "
                    f"limits at {APPROACH_DPS:g} deg/s: blocked or not answering? "
                    "Torque is off again; free the joint and retry")
            self.clock.sleep(0.01)
        for i in indices:
            self.commissioning.append(
                f"{self.describe(int(i))} rested outside its limits at torque-on: brought "
                f"in at {APPROACH_DPS:g} deg/s")

    def disable_torque(self) -> list[str]:
        """Torque off on every servo and watchdog cleared; returns the servos that failed.

        A broadcast Sync Write first (reaches every servo at once), then a checked
        write per servo. Never raises for a servo that does not answer.
        """
        failed: list[str] = []
        with self._lock:
            if not self._transport.is_open:
                was_on, self._torque_on = self._torque_on, False
                return [f"all servos: port {self.port} is closed"] if was_on else []
            try:
                self._sync_write(Reg.TORQUE_ENABLE, [0] * self._n)
            except DeviceError as exc:
                return [f"all servos: {exc}"]
            for i in range(self._n):
                try:
                    self.write_register(i, Reg.TORQUE_ENABLE, 0)
                    self.write_register(i, Reg.BUS_WATCHDOG, 0)
                except DeviceError as exc:
                    failed.append(f"{self.describe(i)}: {exc}")
            self._torque_on = False
        for f in failed:
            log.error("torque off failed: %s", f)
        return failed

    # ------------------------------------------------------------------ close
    def close(self) -> None:
        """Torque off (if on) and close the port. Safe to call more than once."""
        with self._lock:
            try:
                if self._torque_on:
                    self.disable_torque()
            finally:
                self._transport.close()
                self._connected = False

    def __enter__(self) -> DynamixelBus:
        self.connect()
        return self


class _TorqueContext:
    """What :meth:`DynamixelBus.torque` returns (see there)."""

    def __init__(
        self, bus: DynamixelBus, handle_signals: bool, on_signal: Callable[[str], None] | None
    ) -> None:
        self.bus = bus
        self.handle_signals = handle_signals
        self.on_signal = on_signal
        self.signals_seen = 0
        self._cleaning = False
        self._saved: dict[int, object] = {}
        self.failed: list[str] = []

    def _handler(self, signum: int, frame: FrameType | None) -> None:
        name = signal.Signals(signum).name
        if self._cleaning:
            log.warning("%s during torque-off: finishing the torque-off first", name)
            return
        self.signals_seen += 1
        if self.on_signal is not None and self.signals_seen == 1:
            self.on_signal(name)
            return
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        raise SafetyStop(f"{name} received: stopping the servos with torque off")

    def _install(self) -> None:
        if not self.handle_signals or threading.current_thread() is not threading.main_thread():
            return
        for sig in (signal.SIGTERM, signal.SIGINT):
            self._saved[sig] = signal.signal(sig, self._handler)

    def _restore(self) -> None:
        for sig, old in self._saved.items():
            signal.signal(sig, old)  # type: ignore[arg-type]
        self._saved.clear()

    def __enter__(self) -> DynamixelBus:
        if self.bus.torque_enabled:
            raise DeviceError("torque is already on: torque() contexts do not nest")
        self._install()
        try:
            self.bus._enable_torque()
        except BaseException:
            self._off()
            raise
        return self.bus

    def _off(self) -> None:
        self._cleaning = True
        try:
            self.failed = self.bus.disable_torque()
        finally:
            self._restore()
            self._cleaning = False

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._off()
        if self.failed and exc_type is None:
            raise DeviceError("torque off failed: " + "; ".join(self.failed))
