"""Transports: bytes in and out of a Dynamixel bus, with deadlines.

:class:`Transport` is the ABC the driver talks to: it frames packets and reads
against deadlines on the injected :class:`Clock`; a concrete transport only says
how bytes are sent and how to wait for the next ones (tests pass a fake one).
:class:`SerialTransport` is the real port: it is opened with dynamixel-sdk's
``PortHandler`` (pyserial underneath, the SDK's list of baud rates); reading and
waiting are done here on the port's file descriptor with ``select``, in place of
the SDK's busy-wait on wall time.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import select
import struct
import termios
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
from dynamixel_sdk.port_handler import PortHandler

from handrig.clock import Clock
from handrig.devices.servo.codec import HEADER, MAX_PACKET_LEN, packet_length
from handrig.devices.servo.wire import wire_time_s
from handrig.errors import DeviceError, DeviceTimeoutError

# FTDI adapters' default latency timer is 16 ms; 1 ms is the usual setting (REFERENCE.md 1).
LATENCY_TIMER_WANTED_MS = 1
MAX_POLLS = 100_000  # bounds a poll loop even on a clock that does not move
# A write the port has taken none of for this long (plus the bytes' own wire time) has
# met a wedged adapter: the kernel's buffer is full (about 19 KB on a pty, 4 KB in a
# USB serial driver: a fifth of a second or more of our traffic already waiting).
WRITE_TIMEOUT_S = 0.2
# A port whose queue has not shrunk for this long (plus the wire time of a USB
# transfer's worth of it) has stopped draining, long before its buffer is full. On a
# pseudo-terminal, whose queue cannot be seen, ANSWER_STALL_S without a byte and no
# answer to at least UNANSWERED_WEDGED state reads: longer, as an emulator starved of
# CPU on a loaded machine looks the same for a while.
DRAIN_STALL_S = 0.3
ANSWER_STALL_S = 0.5
UNANSWERED_WEDGED = 5
DRAIN_CHUNK_BYTES = 512  # a USB serial driver drains its queue a bulk transfer at a time
# Unix98 pseudo-terminal slaves (/dev/pts/N): Linux's devices.txt, majors 136-143
PTY_SLAVE_MAJORS = range(136, 144)
_SYSFS_LATENCY = "/sys/bus/usb-serial/devices/{name}/latency_timer"


def is_pseudo_terminal(fd: int) -> bool:
    """True when ``fd`` is a pseudo-terminal's slave: a program (an emulator, a network
    bridge), not a UART, answers on the other side, on the host's own CPUs."""
    return os.major(os.fstat(fd).st_rdev) in PTY_SLAVE_MAJORS


@dataclass(frozen=True)
class LatencyReport:
    """What was found and done about the USB adapter's latency timer."""

    path: str | None  # the sysfs file, or None when the port has none
    before_ms: int | None
    after_ms: int | None
    note: str


class Transport(ABC):
    """Bytes to and from one bus, read against deadlines on ``clock``.

    ``read_packet(deadline_s)`` returns one framed packet (header, LEN-sized body)
    or ``None`` when the deadline passes; garbage before a header is skipped and
    counted in ``skipped_bytes``. A subclass says how bytes go out (``write``) and
    how to wait for the next ones (``_receive``, ``_take_pending``). Not thread-safe
    on its own: the bus holds a lock.
    """

    def __init__(self, port: str, baud: int, clock: Clock) -> None:
        self.port = port
        self.baud = baud
        self.clock = clock
        self._buf = bytearray()
        self.skipped_bytes = 0
        self.bytes_written = 0
        self.bytes_read = 0
        self.last_rx_s = -np.inf  # clock time bytes last came in
        self.wedged = False  # the port stopped draining (set by write)
        self.unanswered = 0  # waits for an answer that ended with no byte since the last byte
        self.judging_answers = False  # see judge_answers
        # a pseudo-terminal (set by open): a program answers, on the host's CPUs, so a
        # reply can come late by a scheduler's slice; its output queue cannot be seen
        self.pty = False

    @property
    @abstractmethod
    def is_open(self) -> bool:
        """True between ``open()`` and ``close()``."""

    @abstractmethod
    def open(self) -> None:
        """Open the bus; DeviceError naming the port and the fix if impossible."""

    @abstractmethod
    def close(self) -> None:
        """Close the bus (safe to call twice)."""

    @abstractmethod
    def write(self, data: bytes | memoryview) -> None:
        """Send ``data`` completely (counted in ``bytes_written``); DeviceError if not."""

    @abstractmethod
    def _receive(
        self, deadline_s: float, spin_from_s: float | None, spin_until_s: float
    ) -> bytes:
        """The next bytes to arrive, or b"" once ``deadline_s`` passes without any.

        From ``spin_from_s`` until ``spin_until_s`` (clock times) a transport may
        poll instead of sleeping; a fake may ignore both."""

    @abstractmethod
    def _take_pending(self) -> bytes:
        """Bytes that have already arrived, without waiting (b"" if none)."""

    def judge_answers(self, on: bool) -> None:
        """Whether a port whose queue cannot be seen is judged by its answers (see
        :meth:`SerialTransport._judge_drain`): on while torque is on and the loop
        reads every servo; off while commissioning probes servos that may not answer
        (a missing one, Fast Sync Read on firmware without it) and at torque-off."""
        self.judging_answers = bool(on)
        self.unanswered = 0

    def latency_timer(self, *, set_to_ms: int = LATENCY_TIMER_WANTED_MS) -> LatencyReport:
        """The USB adapter's latency timer, checked and set (none by default)."""
        return LatencyReport(None, None, None, f"no USB latency timer on {self.port}: skipped")

    def _check_open(self) -> None:
        if not self.is_open:
            raise DeviceError(f"servo port {self.port} is not open (call connect() first)")

    def _fill(
        self, deadline_s: float, spin_from_s: float | None = None, spin_until_s: float = np.inf,
        *, answer: bool = False,
    ) -> bool:
        """Wait until bytes arrive (appended to the buffer) or the deadline; True if some did.
        ``answer``: the wait was for the first answer to a request several servos answer
        (a state read), counted in ``unanswered`` when none came."""
        chunk = self._receive(deadline_s, spin_from_s, spin_until_s)
        if not chunk:
            self.unanswered += answer
            return False
        self.unanswered = 0
        self.last_rx_s = self.clock.now()
        self.bytes_read += len(chunk)
        self._buf += chunk
        return True

    def discard_input(self, into: bytearray | None = None, keep: int = 0) -> int:
        """Drop everything already received (buffered and pending); return how many bytes.
        ``into``: the dropped bytes are appended there too, while it holds fewer than
        ``keep`` (a bounded look at what came late)."""
        self._check_open()
        n = self._drop_buffered(into, keep)
        while chunk := self._take_pending():
            n += len(chunk)
            self.last_rx_s = self.clock.now()
            self.unanswered = 0
            if into is not None and len(into) < keep:
                into += chunk[: keep - len(into)]
        return n

    def _drop_buffered(self, into: bytearray | None, keep: int) -> int:
        """Drop the buffered bytes (copied to ``into`` up to ``keep``); return how many."""
        buf = self._buf
        n = len(buf)
        if into is not None and len(into) < keep:
            into += buf[: keep - len(into)]
        buf.clear()
        return n

    def wait_quiet(self, quiet_s: float, max_s: float, since_s: float = -np.inf,
                   into: bytearray | None = None, keep: int = 0) -> int:
        """Discard input until none has come for ``quiet_s``, counting from ``since_s``
        or the last byte received, whichever is later (at most ``max_s``); return bytes.
        ``into`` and ``keep``: as :meth:`discard_input`.

        The bus is half duplex: a request sent while a late reply is still coming
        would collide with it on a real bus (and queue behind it in the emulator).
        """
        self._check_open()
        n = self.discard_input(into, keep)
        end = self.clock.now() + max_s
        while True:
            now = self.clock.now()
            quiet_until = max(since_s, self.last_rx_s) + quiet_s
            if now >= quiet_until or now >= end:
                return n
            if not self._fill(min(end, quiet_until)):
                return n
            n += self._drop_buffered(into, keep)

    def read_exact(
        self, n: int, deadline_s: float, spin_from_s: float | None = None,
        gap_s: float | None = None, spin_until_s: float = np.inf, *, answer: bool = False,
    ) -> bytes:
        """Up to ``n`` bytes: all ``n`` unless the deadline passed first (then fewer).

        ``spin_from_s``: poll instead of sleeping from that clock time on (see
        ``_fill``). ``gap_s``: once bytes flow, give up when none arrive for this
        long, counting from the call (for the rest of a reply whose start has come:
        a reply cut short then ends early instead of at the deadline). ``answer``: see
        ``_fill``.
        """
        self._check_open()
        buf = self._buf
        if gap_s is not None and len(buf) < n:
            deadline_s = min(deadline_s, self.clock.now() + gap_s)
        while len(buf) < n:
            if not self._fill(deadline_s, spin_from_s, spin_until_s, answer=answer):
                break
            if gap_s is not None:
                deadline_s = min(deadline_s, self.clock.now() + gap_s)
        out = bytes(buf[:n])
        del buf[:n]
        return out

    def read_packet(self, deadline_s: float, *, answer: bool = False) -> bytes | None:
        """The next framed packet (not CRC-checked), or None at the deadline.

        Bytes before a ``FF FF FD 00`` header are skipped; a LEN beyond the
        protocol's maximum is taken as a false header and skipped too. A packet cut
        short by the deadline is left in the buffer and None is returned. ``answer``:
        see ``_fill``.
        """
        self._check_open()
        buf = self._buf
        while True:
            start = buf.find(HEADER)
            if start < 0:
                keep = min(len(buf), 3)
                self.skipped_bytes += len(buf) - keep
                del buf[: len(buf) - keep]
            elif start > 0:
                self.skipped_bytes += start
                del buf[:start]
                continue
            elif len(buf) >= 7:
                total = packet_length(buf)
                if total > MAX_PACKET_LEN or total < 10:
                    self.skipped_bytes += 1
                    del buf[:1]
                    continue
                if len(buf) >= total:
                    out = bytes(buf[:total])
                    del buf[:total]
                    return out
            if not self._fill(deadline_s, answer=answer):
                return None


class SerialTransport(Transport):
    """One serial port (dynamixel-sdk's PortHandler), waited on with ``select``."""

    def __init__(self, port: str, baud: int, clock: Clock) -> None:
        super().__init__(port, baud, clock)
        self._handler: PortHandler | None = None
        self._fd = -1
        self.queued = 0  # bytes in the driver's output queue at the last write (TIOCOUTQ)
        self._drained_s = -np.inf  # when the queue was last seen empty or shrinking
        self._outq = bytearray(4)  # TIOCOUTQ's answer, reused

    @property
    def is_open(self) -> bool:
        return self._handler is not None

    def _check_open(self) -> None:
        if self._handler is None:  # the base class's check, without the property call
            raise DeviceError(f"servo port {self.port} is not open (call connect() first)")

    def open(self) -> None:
        """Open the port at ``baud`` (SDK PortHandler); DeviceError if impossible."""
        handler = PortHandler(self.port)
        try:
            ok = handler.setBaudRate(self.baud)
        except Exception as exc:  # pyserial raises SerialException, OSError, ValueError
            raise DeviceError(
                f"cannot open servo port {self.port}: {exc} (check the cable, the path and "
                "that you may use it: e.g. add yourself to the 'dialout' group)"
            ) from None
        if not ok:
            raise DeviceError(
                f"dynamixel-sdk refuses baud {self.baud} on {self.port} "
                "(allowed: 9600 ... 4000000 from the SDK's list)"
            )
        fd = handler.ser.fileno()
        try:  # as pyserial's exclusive=True: another handrig (or such a client) is refused
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handler.closePort()
            raise DeviceError(
                f"servo port {self.port} is busy: another program has it open (another "
                f"handrig run?); find it with `fuser {self.port}`") from None
        self._handler = handler
        self._fd = fd
        os.set_blocking(self._fd, False)
        self._buf.clear()
        self.wedged = False
        self.judge_answers(False)
        self.queued = 0
        self._drained_s = self.clock.now()
        self.pty = is_pseudo_terminal(fd)

    def close(self) -> None:
        """Close the port; after a timed-out write the bytes still queued are dropped
        first (closing a serial port waits for its output to drain: up to 30 s)."""
        if self._handler is not None:
            try:
                if self.wedged:
                    with contextlib.suppress(OSError, termios.error):
                        termios.tcflush(self._fd, termios.TCOFLUSH)
                self._handler.closePort()
            finally:
                self._handler = None
                self._fd = -1

    def write(self, data: bytes | memoryview) -> None:
        """Send ``data`` completely; DeviceError if the port went away, DeviceTimeoutError
        naming the port when it has stopped draining: a wedged adapter. One ``os.write``
        in the usual case (the goals' write is on the cycle's critical path), then the
        port's queue is judged (:meth:`_judge_drain`); a write the port takes none of
        waits at most ``WRITE_TIMEOUT_S`` plus the bytes' wire time."""
        view = data
        try:
            n = os.write(self._fd, view)
            if n != len(view):
                self._write_rest(memoryview(view)[n:])
        except BlockingIOError:
            self._write_rest(memoryview(view))
        except OSError as exc:
            self._check_open()  # closed: say so rather than "bad file descriptor"
            raise DeviceError(f"write to servo port {self.port} failed: {exc}") from None
        self.bytes_written += len(data)
        self._judge_drain(len(data))

    def _judge_drain(self, written: int) -> None:
        """Whether the port still drains, from what is queued against what the wire
        should have carried, not from the buffer filling (a second of goals on a pty).

        A serial driver reports its output queue (TIOCOUTQ: a USB serial driver counts
        its FIFO and the transfer in flight): a queue that was not seen empty or
        shrinking for ``DRAIN_STALL_S`` plus the wire time of a transfer's worth is
        wedged. A pseudo-terminal reports 0 whatever the program at its other end has
        not read (its bytes go straight to that side's input), so there the only sign
        of draining is an answer: no answer to ``UNANSWERED_WEDGED`` state reads in a row
        (reads several servos answer; single-servo commands are not counted) and no
        byte for ``ANSWER_STALL_S`` is taken as the program serving it stopped (only
        while :meth:`judge_answers` is on)."""
        now = self.clock.now()
        if self.pty:
            # before the first answer (all servos missing?) commissioning says why
            if (self.judging_answers and self.unanswered >= UNANSWERED_WEDGED
                    and np.isfinite(self.last_rx_s)
                    and now - self.last_rx_s > ANSWER_STALL_S):
                self.wedged = True
                raise DeviceTimeoutError(
                    f"servo port {self.port} answered none of the last {self.unanswered} "
                    f"state reads, for {now - self.last_rx_s:.2f} s (a pseudo-terminal: its "
                    "queue cannot be seen, answers are the sign it drains): the emulator "
                    "(or the program serving the port) has stopped draining it")
            return
        queued = self._output_queue()
        if queued is None:
            return  # a driver without an output queue to report: the deadline alone
        # empty at the last look (however long ago), empty now, or some gone since
        if queued == 0 or self.queued == 0 or queued < self.queued + written:
            self._drained_s = now
        self.queued = queued
        stall_s = now - self._drained_s
        if stall_s > DRAIN_STALL_S + wire_time_s(min(queued, DRAIN_CHUNK_BYTES), self.baud):
            self.wedged = True
            raise DeviceTimeoutError(
                f"servo port {self.port} drained none of its {queued} queued bytes for "
                f"{stall_s:.2f} s (the wire carries them in "
                f"{wire_time_s(queued, self.baud) * 1e3:.1f} ms): the USB adapter has "
                "stopped draining; unplug and replug the adapter")

    def _output_queue(self) -> int | None:
        """Bytes in the driver's output queue (TIOCOUTQ), None if it cannot say."""
        try:
            fcntl.ioctl(self._fd, termios.TIOCOUTQ, self._outq, True)
        except OSError:
            return None
        return int(struct.unpack("i", self._outq)[0])

    def _write_rest(self, view: memoryview) -> None:
        """The rest of a write the port did not take at once, against a deadline."""
        clock, fd = self.clock, self._fd
        timeout_s = WRITE_TIMEOUT_S + wire_time_s(len(view), self.baud)
        end = clock.now() + timeout_s
        while view:
            now = clock.now()
            if now >= end:
                self.wedged = True
                raise DeviceTimeoutError(
                    f"servo port {self.port} took no bytes for {timeout_s:.2f} s "
                    f"({len(view)} bytes of a write still waiting): the USB adapter (or the "
                    "emulator serving the port) has stopped draining; unplug and replug "
                    "the adapter")
            wait = min(end - now, 0.01)
            try:
                _, ready, _ = select.select([], [fd], [], wait)
                if not ready:
                    self.clock.sleep_until(now + wait)  # a fake clock learns time passed
                    continue
                view = view[os.write(fd, view):]
            except (BlockingIOError, InterruptedError):
                continue

    def _receive(
        self, deadline_s: float, spin_from_s: float | None, spin_until_s: float
    ) -> bytes:
        """Wait for bytes until the deadline (b"" if none came).

        From ``spin_from_s`` until ``spin_until_s`` (clock times), poll without
        sleeping: a wake-up from ``select`` costs tens of microseconds, which a
        cycle near the wire-time limit notices. The poll is bounded by that window
        and by ``MAX_POLLS`` as well as the deadline.
        """
        fd = self._fd
        polls = 0
        while True:
            now = self.clock.now()
            remaining = deadline_s - now
            if remaining <= 0:
                return b""
            if spin_from_s is not None and now >= spin_until_s:
                spin_from_s = None
            if spin_from_s is not None and now >= spin_from_s:
                try:
                    chunk = os.read(fd, 4096)
                except BlockingIOError:
                    chunk = b""
                except OSError as exc:
                    raise DeviceError(f"read from servo port {self.port} failed: {exc}") from None
                if not chunk:  # nothing yet (termios VMIN=0 reads return empty)
                    polls += 1
                    if polls >= MAX_POLLS:
                        spin_from_s = None
                    continue
            else:
                wait = remaining if spin_from_s is None else min(remaining, spin_from_s - now)
                try:
                    ready, _, _ = select.select([fd], [], [], wait)
                except InterruptedError:
                    continue
                if not ready:
                    # No bytes for `wait` seconds: let a fake clock know that time passed.
                    if wait < remaining:
                        self.clock.sleep_until(now + wait)
                        continue
                    self.clock.sleep_until(deadline_s)
                    return b""
                try:
                    chunk = os.read(fd, 4096)
                except BlockingIOError:
                    continue
                except OSError as exc:
                    raise DeviceError(f"read from servo port {self.port} failed: {exc}") from None
            if not chunk:
                raise DeviceError(f"servo port {self.port} closed (adapter unplugged?)")
            return chunk

    def _take_pending(self) -> bytes:
        try:
            return os.read(self._fd, 4096)
        except BlockingIOError:
            return b""
        except OSError as exc:
            raise DeviceError(f"read from servo port {self.port} failed: {exc}") from None

    def latency_timer(self, *, set_to_ms: int = LATENCY_TIMER_WANTED_MS) -> LatencyReport:
        """Check the USB adapter's latency timer in sysfs and set it to ``set_to_ms``.

        Only FTDI-style adapters (``/dev/ttyUSBn``) have one; a pseudo-terminal or
        an ACM device does not, which the report says.
        """
        real = os.path.realpath(self.port)
        name = os.path.basename(real)
        if not re.fullmatch(r"ttyUSB\d+", name):
            return LatencyReport(
                None, None, None, f"no USB latency timer on {real}: skipped"
            )
        path = _SYSFS_LATENCY.format(name=name)
        try:
            with open(path) as f:
                before = int(f.read().strip())
        except (OSError, ValueError) as exc:
            return LatencyReport(path, None, None, f"cannot read {path}: {exc}: skipped")
        if before <= set_to_ms:
            return LatencyReport(path, before, before, f"latency timer {before} ms: ok")
        try:
            with open(path, "w") as f:
                f.write(f"{set_to_ms}\n")
        except OSError as exc:
            return LatencyReport(
                path, before, before,
                f"latency timer is {before} ms and could not be set ({exc}): every read "
                f"waits up to {before} ms; fix: echo {set_to_ms} | sudo tee {path}",
            )
        return LatencyReport(
            path, before, set_to_ms, f"latency timer set from {before} to {set_to_ms} ms"
        )
