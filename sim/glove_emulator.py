"""A glove on a pseudo-terminal: streams a recording in real time, byte for byte.

``GloveEmulator(recording, fmt)`` opens a pty, puts it in raw mode and, from a
background thread, writes one frame per sample at the glove's rate: handrig
frames (``firmware_protocol/SPEC.md``) or OpenGloves alpha lines. Whatever reads
``port_path`` (``SerialGlove``, ``handrig run --glove``) sees what a USB glove
would send. Fault switches for tests: :meth:`inject_garbage`,
:meth:`corrupt_next`, :meth:`pause` / :meth:`resume`, :meth:`hang_up`.
:meth:`play` switches to another recording while streaming (a glove that
changes pose on cue, :mod:`sim.calibration_motion`).

Example::

    with GloveEmulator(read_glove_recording("demo.csv"), "frames") as emu:
        glove = SerialGlove(emu.port_path, "frames", clock=MonotonicClock())
"""

from __future__ import annotations

import contextlib
import os
import random
import threading
import time
import tty
from collections.abc import Callable
from types import TracebackType
from typing import Literal

import numpy as np

from firmware_protocol.glove import MAX_CHANNELS, GloveFrame, encode_frame
from firmware_protocol.opengloves import BUTTON_LETTERS, OpenGlovesLine, encode_line
from handrig.clock import Clock, MonotonicClock
from handrig.devices.glove_recording import GloveRecording
from handrig.errors import DataError
from handrig.realtime import SHORT_SLICE_NS, fair_slice_ns

EmulatorFormat = Literal["frames", "opengloves"]


class GloveEmulator:
    """Streams ``recording`` over a pty in real time (see the module docstring).

    ``rate_hz``: send at this fixed rate, each time the recording's sample due
    then (``None``: send each recorded sample at its own ``t_s``). ``loop``: start
    over at the end (at ``loop_from_s`` of the recording, 0 = its start);
    otherwise the emulator stops sending after the last sample (:attr:`done` is
    set) and keeps the port open until :meth:`close`.
    OpenGloves: the first five channels are the fingers (clipped to 0..analog_max),
    channels 5..9 if present the splays; buttons bit 0 is sent as
    ``estop_letter``, bits 1..8 as H..O.

    ``on_send(t_s, seq, index)``, if given, is called from the streaming thread after
    each frame was written to the pty: ``t_s`` (taken just before the write) on
    CLOCK_MONOTONIC (the clock the rig's
    :class:`~handrig.clock.MonotonicClock` reads on Linux), the frame's sequence number
    and the recording's sample index. It is how a latency is measured from outside the
    rig process.
    """

    def __init__(
        self,
        recording: GloveRecording,
        fmt: EmulatorFormat = "frames",
        *,
        rate_hz: float | None = None,
        loop: bool = False,
        loop_from_s: float = 0.0,
        clock: Clock | None = None,
        analog_max: int = 4095,
        estop_letter: str = "N",
        seed: int = 0,
        on_send: Callable[[float, int, int], None] | None = None,
    ) -> None:
        self.on_send = on_send
        if fmt not in ("frames", "opengloves"):
            raise DataError(f"glove format {fmt!r} unknown: use 'frames' or 'opengloves'")
        if estop_letter not in BUTTON_LETTERS:
            raise DataError(f"e-stop letter {estop_letter!r} is not an OpenGloves button "
                            f"(one of {BUTTON_LETTERS})")
        if rate_hz is not None and not 1.0 <= rate_hz <= 5000.0:
            raise DataError(f"glove rate {rate_hz} Hz out of range 1..5000")
        self._check_recording(recording, fmt, loop_from_s)
        self.recording = recording
        self.fmt: EmulatorFormat = fmt
        self.rate_hz = rate_hz
        self.loop = loop
        self.loop_from_s = loop_from_s
        self.clock: Clock = clock or MonotonicClock()
        self.analog_max = analog_max
        self.estop_letter = estop_letter
        self._rng = random.Random(seed)
        self._master = -1
        self._slave = -1
        self.port_path = ""
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._paused = threading.Event()
        self.done = threading.Event()
        """Set when a non-looping emulator has sent its last sample."""
        self._lock = threading.Lock()
        self._garbage: list[bytes] = []
        self._corrupt = 0
        self._next: tuple[GloveRecording, bool, float] | None = None
        self.frames_sent = 0
        self.bytes_sent = 0
        self.bytes_dropped = 0
        """Bytes the pty would not take (nobody reading): a real UART loses them too."""

    @staticmethod
    def _check_recording(recording: GloveRecording, fmt: str, loop_from_s: float) -> None:
        if len(recording) == 0:
            raise DataError("glove recording is empty: nothing to stream")
        if fmt == "opengloves" and recording.n_channels < 5:
            raise DataError(f"OpenGloves needs 5 finger channels, the recording has "
                            f"{recording.n_channels}")
        if fmt == "frames" and recording.n_channels > MAX_CHANNELS:
            raise DataError(f"a frame carries at most {MAX_CHANNELS} channels, the recording "
                            f"has {recording.n_channels}")
        span_s = float(recording.t_s[-1] - recording.t_s[0])
        if not 0.0 <= loop_from_s < max(span_s, 1e-9):
            raise DataError(f"loop_from_s {loop_from_s:g} s outside the recording "
                            f"(0..{span_s:g} s)")

    # -- lifecycle ----------------------------------------------------------

    def start(self) -> GloveEmulator:
        """Open the pty and start streaming. Returns self."""
        if self._thread is not None:
            return self
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.port_path = os.ttyname(self._slave)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="glove-emulator", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop streaming and close the pty. Idempotent."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self._close_fds()

    def _close_fds(self) -> None:
        for fd in (self._master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = -1

    def __enter__(self) -> GloveEmulator:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- fault switches -------------------------------------------------------

    def inject_garbage(self, n_bytes: int, *, with_zeros: bool = True) -> None:
        """Send ``n_bytes`` random bytes before the next frame (zeros included unless told)."""
        lo = 0 if with_zeros else 1
        burst = bytes(self._rng.randint(lo, 255) for _ in range(n_bytes))
        with self._lock:
            self._garbage.append(burst)

    def corrupt_next(self, n_frames: int) -> None:
        """Corrupt the next ``n_frames``: frames get a wrong CRC (stuffing kept valid);
        OpenGloves lines are cut in the middle (their start then merges with the next)."""
        with self._lock:
            self._corrupt += n_frames

    def pause(self) -> None:
        """Stop streaming (a glove that goes quiet); the port stays open."""
        self._paused.set()

    def resume(self) -> None:
        """Stream again after :meth:`pause`, from the sample due now."""
        self._paused.clear()

    def hang_up(self) -> None:
        """The glove disappears: stop and close the pty; readers then get end-of-file
        (``read`` returns no bytes although ``select`` says readable) or an I/O error."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
            self._thread = None
        self._close_fds()

    def play(self, recording: GloveRecording, *, loop: bool = False,
             loop_from_s: float = 0.0) -> None:
        """Stream ``recording`` from its start, from the next sample on (``loop`` and
        ``loop_from_s`` as in the constructor); :attr:`done` is cleared."""
        self._check_recording(recording, self.fmt, loop_from_s)
        with self._lock:
            self._next = (recording, loop, loop_from_s)
        self.done.clear()

    # -- streaming ------------------------------------------------------------

    def _sample_index(self, elapsed_s: float) -> int:
        t = self.recording.t_s - self.recording.t_s[0]
        return int(np.searchsorted(t, elapsed_s, side="right")) - 1

    def encode_sample(self, i: int, seq: int, t_us: int) -> bytes:
        """Sample ``i`` of the recording on the wire (sequence ``seq``, timestamp ``t_us``)."""
        rec = self.recording
        raw = rec.raw[i]
        b = int(rec.buttons[i])
        if self.fmt == "frames":
            q = None if rec.quat_xyzw is None else rec.quat_xyzw[i]
            quat = None if q is None or np.isnan(q).any() else (
                float(q[0]), float(q[1]), float(q[2]), float(q[3]))
            channels = tuple(int(v) for v in np.clip(np.rint(raw), 0, 65535))
            frame = GloveFrame(seq, t_us & 0xFFFFFFFF, channels, quat, b & 0xFF)
            return encode_frame(frame)
        vals = [int(v) for v in np.clip(np.rint(raw), 0, self.analog_max)]
        buttons = {letter for k, letter in enumerate(BUTTON_LETTERS) if b & (2 << k)}
        if b & 1:
            buttons.add(self.estop_letter)
        splay = tuple(vals[5:10]) if len(vals) >= 10 else (None,) * 5
        line = OpenGlovesLine(
            (vals[0], vals[1], vals[2], vals[3], vals[4]),
            buttons=frozenset(buttons),
            splay=splay,  # type: ignore[arg-type]
        )
        return encode_line(line)

    def _corrupted(self, wire: bytes) -> bytes:
        if self.fmt == "frames":
            b = bytearray(wire)
            flipped = b[-2] ^ 0x5A  # the CRC's high byte (or its code byte): never 0x00
            b[-2] = flipped if flipped else 0x01
            return bytes(b)
        return wire[: max(1, len(wire) // 2)]

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                n = os.write(self._master, view)
            except BlockingIOError:
                self.bytes_dropped += len(view)
                return
            self.bytes_sent += n
            view = view[n:]

    def _drain_input(self) -> None:
        with contextlib.suppress(OSError):
            os.read(self._master, 4096)  # host-to-glove bytes (force feedback): discarded

    @staticmethod
    def _timing(rec: GloveRecording) -> tuple[float, float]:
        """(span, typical gap between samples) in seconds."""
        gap_s = float(np.median(np.diff(rec.t_s))) if len(rec) > 1 else 0.01
        return float(rec.t_s[-1] - rec.t_s[0]), gap_s

    def _run(self) -> None:
        fair_slice_ns(SHORT_SLICE_NS)  # a glove keeps its own clock: sends ahead of busy threads
        t0 = t_first = self.clock.now()
        k = 0
        seq = 0
        rec = self.recording
        span_s, gap_s = self._timing(rec)
        while not self._stop.is_set():
            with self._lock:
                switch, self._next = self._next, None
            if switch is not None:
                self.recording, self.loop, self.loop_from_s = switch
                rec = self.recording
                span_s, gap_s = self._timing(rec)
                t0, k = self.clock.now(), 0
            lap_s = span_s + gap_s
            if self.rate_hz is not None:
                elapsed = k / self.rate_hz
            elif self.loop and self.loop_from_s > 0:
                elapsed = k * gap_s  # a loop that restarts mid-recording: evenly spaced
            else:
                lap, idx = divmod(k, len(rec))
                elapsed = lap * lap_s + float(rec.t_s[idx] - rec.t_s[0])
            due = t0 + elapsed
            self._sleep_until(due)
            if self._stop.is_set():
                return
            if self.loop:
                if elapsed >= lap_s:
                    tail = lap_s - self.loop_from_s
                    elapsed = self.loop_from_s + (elapsed - lap_s) % tail
            elif elapsed > span_s + 1e-9:
                self.done.set()
                while not self._stop.is_set() and self._next is None:
                    self._stop.wait(0.01)
                continue
            i = (self._sample_index(elapsed)
                 if self.rate_hz is not None or (self.loop and self.loop_from_s > 0)
                 else k % len(rec))
            k += 1
            if self._paused.is_set():
                continue
            # the glove's clock: time since streaming began, across loops and switches
            wire = self.encode_sample(i, seq, round((due - t_first) * 1e6))
            seq = (seq + 1) & 0xFFFF
            with self._lock:
                garbage, self._garbage = self._garbage, []
                if self._corrupt:
                    self._corrupt -= 1
                    wire = self._corrupted(wire)
            try:
                for burst in garbage:
                    self._write(burst)
                sent_at = time.clock_gettime(time.CLOCK_MONOTONIC)  # handed to the pty next
                self._write(wire)
                self._drain_input()
            except OSError:
                return  # the pty was closed under us (hang_up)
            self.frames_sent += 1
            if self.on_send is not None:
                self.on_send(sent_at, (seq - 1) & 0xFFFF, i)

    def _sleep_until(self, t: float) -> None:
        # sleep in short slices so close() and hang_up() are prompt
        while not self._stop.is_set():
            remaining = t - self.clock.now()
            if remaining <= 0:
                return
            if remaining > 0.05:
                self._stop.wait(0.05)
            else:
                self.clock.sleep_until(t)
                return
