"""A glove on a serial port: :class:`SerialGlove`.

Reads the handrig frame format (``firmware_protocol/SPEC.md``) or the OpenGloves
alpha line format, on a background thread or (``reader="poll"``) inside the loop.

A frame's channel count is checked before it becomes a sample: ``channels`` if
given, else the count the glove settles on (:data:`LOCK_FRAMES` good frames in a
row with the same count, at least ``min_channels``, after each open). A frame
with another count, valid CRC or not, is counted in ``channel_errors`` and
dropped: to the loop it looks like a garbled glove, never like a sample.

``SerialGlove(reader="poll")`` reads without a thread instead: each ``latest()``
does one non-blocking read and decodes what is there (a few microseconds, no
GIL hand-over between threads); the frame's ``host_time_s`` is then the time of
that read.
"""

from __future__ import annotations

import contextlib
import errno
import math
import os
import select
import termios
import threading
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np

from firmware_protocol.glove import BUTTON_RELAX, MAX_CHANNELS, FrameDecoder
from firmware_protocol.opengloves import BUTTON_LETTERS, CHANNEL_KEYS, LineDecoder
from handrig.clock import Clock
from handrig.devices.glove.source import GloveSample, GloveSource, GloveStats
from handrig.devices.glove_status import change_messages
from handrig.errors import DeviceError

GloveFormat = Literal["frames", "opengloves"]

LOCK_FRAMES = 3
"""Good frames in a row with one channel count that fix the count a glove sends."""


class SerialGlove(GloveSource):
    """A glove on a serial port (USB CDC, UART, or a pty from the glove emulator).

    ``fmt`` is ``"frames"`` (handrig frames, ``firmware_protocol/SPEC.md``) or
    ``"opengloves"`` (alpha lines; ``analog_max`` 1023 or 4095; the button letter
    ``estop_letter`` becomes buttons bit 0, the letters H..O bits 1..8). A
    background thread reads whatever bytes arrive, stamps them with ``clock.now()``
    and decodes them. If the port goes away the source records a
    :class:`DeviceError` and, with ``reconnect_s`` > 0, tries to reopen the same
    path every ``reconnect_s`` seconds (a replugged USB glove usually returns there).

    ``reader="thread"`` (default) reads on a background thread; ``reader="poll"``
    reads inside :meth:`latest` with non-blocking reads (no thread).
    """

    def __init__(
        self,
        port: str,
        fmt: GloveFormat = "frames",
        *,
        clock: Clock,
        baud: int = 115200,
        analog_max: int = 4095,
        estop_letter: str = "N",
        reconnect_s: float = 0.5,
        poll_s: float = 0.05,
        reader: Literal["thread", "poll"] = "thread",
        channels: int | None = None,
        min_channels: int = 1,
        channel_names: Sequence[str] = (),
    ) -> None:
        super().__init__()
        self.channel_names = tuple(channel_names)
        """Names of the raw channels (their curves), for messages about them."""
        self._status = 0
        if channels is not None and not 0 <= channels <= MAX_CHANNELS:
            raise DeviceError(f"glove channels {channels}: a frame carries 0..{MAX_CHANNELS}")
        if not 0 <= min_channels <= MAX_CHANNELS:
            raise DeviceError(f"glove min_channels {min_channels}: use 0..{MAX_CHANNELS}")
        if channels is not None and channels < min_channels:
            raise DeviceError(f"glove channels {channels} is below min_channels {min_channels}")
        self.channels = channels
        self.min_channels = min_channels
        if fmt not in ("frames", "opengloves"):
            raise DeviceError(f"glove format {fmt!r} unknown: use 'frames' or 'opengloves'")
        if estop_letter not in BUTTON_LETTERS:
            raise DeviceError(f"e-stop letter {estop_letter!r} is not an OpenGloves button "
                              f"(one of {BUTTON_LETTERS})")
        self.port = port
        self.fmt: GloveFormat = fmt
        self.clock = clock
        self.baud = baud
        self.analog_max = analog_max
        self.reconnect_s = reconnect_s
        self.poll_s = poll_s
        if reader not in ("thread", "poll"):
            raise DeviceError(f"glove reader {reader!r} unknown: use 'thread' or 'poll'")
        self.reader = reader
        self._next_reopen_s = -math.inf
        self._estop_bit = 1 << BUTTON_LETTERS.index(estop_letter)
        self._frames = FrameDecoder()
        self._lines = LineDecoder(analog_max)
        # the warm-up's own decoders (:meth:`rehearse`) and the last bytes fed
        self._rehearsal_frames = FrameDecoder()
        self._rehearsal_lines = LineDecoder(analog_max)
        self._last_chunk = b""
        self._serial: Any = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._count = 0
        self._bytes = 0
        self._reconnects = 0
        self._disconnects = 0
        self._lost_at_s = 0.0
        self._last_outage_s = 0.0
        self._channel_errors = 0
        self._expected = channels if channels is not None else 0
        self._candidate = -1  # the count of the good frames in a row before it is fixed
        self._run_length = 0
        self._last_good_s = -math.inf
        self._lock = threading.Lock()

    def _open(self) -> Any:
        import serial  # adapter module: the only place the glove side touches pyserial

        try:
            # exclusive: a second reader of the same glove would take half its frames
            return serial.Serial(self.port, self.baud, timeout=0, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            if isinstance(exc, OSError) and exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK):
                raise DeviceError(
                    f"glove port {self.port} is busy: another program (a second handrig"
                    " run, a glove monitor, a serial terminal) has it open; close that one"
                    " first") from None
            raise DeviceError(
                f"cannot open glove port {self.port}: {exc}; is the glove plugged in? "
                "(pass the right port with --glove PORT; on Linux add your user to 'dialout')"
            ) from None

    @property
    def name(self) -> str:
        return self.port

    def start(self) -> None:
        if self._thread is not None or self._serial is not None:
            return
        self._serial = self._open()
        _nonblocking(self._serial.fileno())
        if self.reader == "poll":
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"glove:{self.port}",
                                        daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self._serial is not None:
            with contextlib.suppress(Exception):  # the port may already be gone
                self._serial.close()
            self._serial = None

    def latest(self) -> GloveSample | None:
        if self.reader == "poll":
            self._poll()
        return super().latest()

    def take(self) -> GloveSample | None:
        """:meth:`latest` without reading the port first: for a loop whose trigger has
        just pumped it (a cycle started by a frame, or after waiting on the port until a
        deadline with nothing arriving), which saves a system call on the frame's path.
        While the port is gone (no descriptor to wait on, so nothing pumps it) it tries
        to reopen it, every ``reconnect_s``, as :meth:`latest` does."""
        if self._serial is None and self.reader == "poll":
            self._poll()
        return super().latest()

    def fileno(self) -> int | None:
        """The open port's descriptor with ``reader="poll"``, for a loop that blocks on it
        until bytes arrive and then calls :meth:`pump`; None with a reader thread or while
        the port is gone."""
        ser = self._serial
        if self.reader != "poll" or ser is None:
            return None
        try:
            return int(ser.fileno())
        except (OSError, ValueError, TypeError):
            return None

    pump_counts = True
    """:meth:`pump` returns how many good frames it decoded."""

    def pump(self) -> int:
        """Read and decode what has arrived, stamped with the clock now (``reader="poll"``;
        never blocks); returns how many good frames that gave. Called as soon as the
        descriptor turns readable, it stamps each frame with the time its last byte
        arrived."""
        if self.reader == "poll":
            before = self._count
            self._poll()
            return self._count - before
        return 0

    def feed(self, data: bytes, now: float) -> None:
        """Decode ``data`` as bytes read from the port at clock time ``now`` (the reader
        thread and :meth:`latest` with ``reader="poll"`` call this; tests may too)."""
        with self._lock:
            self._last_chunk = data
            self._bytes += len(data)
            if self.fmt == "frames":
                self._feed_frames(data, now)
            else:
                self._feed_lines(data, now)

    def _poll(self) -> None:
        ser = self._serial
        if ser is None:
            now = self.clock.now()
            if self.reconnect_s > 0 and now >= self._next_reopen_s:
                self._next_reopen_s = now + self.reconnect_s
                self._reopen_now()
            return
        try:
            fd = ser.fileno()
            for _ in range(8):  # bounded: at most 32 KiB per call
                data = os.read(fd, 4096)  # EAGAIN when empty (VMIN 1, O_NONBLOCK)
                if not data:
                    raise OSError("end of file: the device hung up")
                self.feed(data, self.clock.now())
                if len(data) < 4096:
                    return
        except BlockingIOError:
            return
        except (OSError, ValueError, TypeError) as exc:
            self._lost(exc)
            self._next_reopen_s = self.clock.now() + self.reconnect_s

    def stats(self) -> GloveStats:
        with self._lock:
            since = self.clock.now() - self._last_good_s
            failure = str(self._failure) if self._failure else ""
            if self.fmt == "frames":
                f = self._frames.stats
                return GloveStats(
                    frames_ok=f.frames_ok - self._channel_errors, crc_errors=f.crc_errors,
                    decode_errors=f.errors - f.crc_errors + self._channel_errors,
                    resyncs=f.resyncs + self._channel_errors,
                    garbage_bytes=f.garbage_bytes, seq_gaps=f.seq_gaps,
                    frames_lost=f.frames_lost, bytes_read=self._bytes,
                    reconnects=self._reconnects, time_since_last_good_s=since,
                    failure=failure, channel_errors=self._channel_errors,
                    expected_channels=self._expected, disconnects=self._disconnects,
                    last_outage_s=self._last_outage_s,
                )
            g = self._lines.stats
            return GloveStats(
                frames_ok=g.lines_ok, decode_errors=g.errors, resyncs=g.errors,
                garbage_bytes=g.garbage_bytes, bytes_read=self._bytes,
                reconnects=self._reconnects, time_since_last_good_s=since, failure=failure,
                expected_channels=len(CHANNEL_KEYS), disconnects=self._disconnects,
                last_outage_s=self._last_outage_s,
            )

    def _run(self) -> None:
        while not self._stop.is_set():
            ser = self._serial
            if ser is None:
                if not self._try_reopen():
                    continue
                ser = self._serial
            try:
                fd = ser.fileno()
                ready, _, _ = select.select([fd], [], [], self.poll_s)
                if not ready:
                    continue
                data = os.read(fd, 4096)
                if not data:
                    raise OSError("device reports readiness to read but returned no data")
            except BlockingIOError:
                continue
            except (OSError, ValueError, TypeError) as exc:
                if self._stop.is_set():
                    return
                self._lost(exc)
                continue
            self.feed(data, self.clock.now())

    def _lost(self, exc: BaseException) -> None:
        self._failure = DeviceError(
            f"glove port {self.port} went away ({exc}); "
            + ("retrying every " + f"{self.reconnect_s:g} s" if self.reconnect_s > 0
               else "check the cable and restart")
        )
        self._disconnects += 1
        self._lost_at_s = self.clock.now()
        self._events.append(str(self._failure))
        with contextlib.suppress(Exception):  # the port is already gone
            self._serial.close()
        self._serial = None

    def _try_reopen(self) -> bool:
        if self.reconnect_s <= 0:
            self._stop.wait(self.poll_s)
            return False
        if self._stop.wait(self.reconnect_s):
            return False
        return self._reopen_now()

    def _reopen_now(self) -> bool:
        try:
            ser = self._open()
            _nonblocking(ser.fileno())
        except (DeviceError, OSError):
            return False
        with self._lock:
            self._serial = ser
            self._frames.reset()
            self._reconnects += 1
            self._last_outage_s = self.clock.now() - self._lost_at_s
            if self.channels is None:  # the glove may come back reflashed: settle again
                self._expected, self._candidate, self._run_length = 0, -1, 0
            self._failure = None
        self._events.append(
            f"glove port {self.port} is back after {self._last_outage_s:.2f} s"
            f" (reconnect {self._reconnects}, {self._disconnects} disconnects so far)")
        return True

    @staticmethod
    def _frame_sample(fr: Any, now: float, count: int) -> GloveSample:
        q = fr.quat_xyzw
        return GloveSample(
            raw=np.array(fr.channels, dtype=np.float64),
            quat=None if q is None else np.array(q, dtype=np.float64),
            buttons=fr.buttons, estop=bool(fr.buttons & BUTTON_RELAX), seq=fr.seq,
            sensor_time_us=fr.timestamp_us, host_time_s=now, count=count, status=fr.status,
        )

    def _line_sample(self, line: Any, now: float, count: int) -> GloveSample:
        bits = line.button_bits()
        estop = bool(bits & self._estop_bit)
        return GloveSample(
            raw=np.array(line.channels(self.analog_max), dtype=np.float64), quat=None,
            buttons=int(estop) | (bits << 1), estop=estop, seq=count & 0xFFFF,
            sensor_time_us=0, host_time_s=now, count=count,
        )

    def _channels_ok(self, n: int) -> bool:
        """Whether a decoded frame with ``n`` channels may become a sample (settling the
        expected count first, see the module docstring)."""
        if self._expected or self.channels is not None:
            if n == self._expected:
                return True
            self._channel_errors += 1
            return False
        if n < self.min_channels:
            self._channel_errors += 1
            self._candidate, self._run_length = -1, 0
            return False
        if n == self._candidate:
            self._run_length += 1
        else:
            self._candidate, self._run_length = n, 1
        if self._run_length >= LOCK_FRAMES:
            self._expected = n
            return True
        return False

    def rehearse(self) -> None:
        """The last bytes read, through decoders of the warm-up's own and into samples
        that are dropped (:meth:`GloveSource.rehearse`): this glove's counters, events,
        channel count and newest sample stay as they were."""
        data = self._last_chunk  # one read: at most 32 KiB (:meth:`_poll`)
        if not data:
            return
        # a partial frame left over is not kept (reset): the next rehearsal starts clean
        if self.fmt == "frames":
            for fr in self._rehearsal_frames.feed(data):
                self._frame_sample(fr, 0.0, 0)
            self._rehearsal_frames.reset()
        else:
            for line in self._rehearsal_lines.feed(data):
                self._line_sample(line, 0.0, 0)
            self._rehearsal_lines.reset()

    def _feed_frames(self, data: bytes, now: float) -> None:
        for fr in self._frames.feed(data):
            if not self._channels_ok(len(fr.channels)):
                continue
            self._count += 1
            self._arrived(self._frame_sample(fr, now, self._count))
            self._last_good_s = now
            if fr.status != self._status:  # the glove's health changed: say so once
                self._events.extend(change_messages(self._status, fr.status, fr.channels,
                                                    self.channel_names))
                self._status = fr.status

    def _feed_lines(self, data: bytes, now: float) -> None:
        for line in self._lines.feed(data):
            self._count += 1
            self._arrived(self._line_sample(line, now, self._count))
            self._last_good_s = now


def _nonblocking(fd: int) -> None:
    """O_NONBLOCK and VMIN 1, VTIME 0: a read of an empty port fails with EAGAIN and
    only a hang-up reads as end of file (pyserial leaves VMIN 0, where both read b"")."""
    os.set_blocking(fd, False)
    try:
        attrs = termios.tcgetattr(fd)
        attrs[6][termios.VMIN] = 1
        attrs[6][termios.VTIME] = 0
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
    except termios.error:
        pass  # not a terminal (a pipe or socket): O_NONBLOCK alone does it
