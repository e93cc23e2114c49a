"""The OSC port: UDP datagrams received in a thread of its own, each parsed and its
cues handed to the dispatcher (:class:`OscReceiver`).

The thread shares the interpreter lock with the loop: were it preempted while holding
the lock (a loaded machine), the loop would wait for it to be scheduled again, so where
the loop runs under SCHED_FIFO the thread runs one priority below (as the view's
feeder): only the loop preempts it. What it may take at that priority is bounded: at
most :data:`MAX_RATE_HZ` datagrams a second (a token bucket); more wait in the
socket's buffer, and what overflows the buffer the kernel drops.
"""

from __future__ import annotations

import contextlib
import select
import socket
import threading
import time
from collections.abc import Callable

from handrig.app.cues.dispatch import CueDispatcher, osc_cue
from handrig.app.cues.osc import parse_packet
from handrig.config.cues import OSC_PREFIX
from handrig.errors import ConfigError
from handrig.realtime import realtime_priority

MAX_DATAGRAM = 65535
_PREFIX = OSC_PREFIX.encode("ascii")
MAX_RATE_HZ = 4000.0
"""Datagrams a second the thread handles at most (a show controller sends tens)."""
BURST = 200


class Bucket:
    """A token bucket: :data:`BURST` datagrams at once, :data:`MAX_RATE_HZ` a second."""

    def __init__(self) -> None:
        self.tokens = float(BURST)
        self.last_s: float | None = None

    def take(self, now_s: float) -> float:
        """One datagram handled at ``now_s``: how long to wait before the next (0: none)."""
        if self.last_s is not None:
            self.tokens = min(float(BURST), self.tokens + (now_s - self.last_s) * MAX_RATE_HZ)
        self.last_s = now_s
        self.tokens -= 1.0
        return -self.tokens / MAX_RATE_HZ if self.tokens < 0.0 else 0.0


class OscReceiver:
    """Listens on ``(host, port)`` (UDP; port 0: any free one, see :attr:`port`) from
    :meth:`start` to :meth:`close`; every message goes to ``dispatcher``: a cue is acted
    on, anything else counted. ``flag`` names the setting in an error (a port taken, a
    host that is not this machine's)."""

    def __init__(self, host: str, port: int, dispatcher: CueDispatcher, *,
                 flag: str = "--osc-in", priority: int = 0) -> None:
        self.dispatcher = dispatcher
        self.priority = priority
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            self._sock.bind((host, port))
        except OSError as exc:
            self._sock.close()
            raise ConfigError(f"cannot listen for OSC there ({exc.strerror})", key=flag,
                              value=f"{host}:{port}",
                              allowed="a free UDP port on an address of this machine "
                              "(e.g. 9000, or 0.0.0.0:9000 for every interface)") from None
        self.host = host
        self.port: int = self._sock.getsockname()[1]
        self._wake_r, self._wake_w = socket.socketpair()
        self._thread: threading.Thread | None = None
        self.on_error: Callable[[BaseException], None] = lambda exc: None

    def start(self) -> OscReceiver:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="handrig-osc-in",
                                            daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        with realtime_priority(self.priority):
            self._receive()

    def _receive(self) -> None:
        sock, wake = self._sock, self._wake_r
        bucket = Bucket()
        while True:
            try:
                ready, _, _ = select.select([sock, wake], [], [])
                if wake in ready:
                    return
                data = sock.recv(MAX_DATAGRAM)
            except OSError as exc:
                self.on_error(exc)
                return
            self.handle(data)
            wait_s = bucket.take(time.monotonic())
            if wait_s > 0.0 and select.select([wake], [], [], wait_s)[0]:
                return  # over the rate, it waited for a token; closed meanwhile

    def handle(self, data: bytes) -> None:
        """One datagram: its messages dispatched, what is no cue counted. A message to an
        address outside ``/handrig/`` is counted unknown unparsed (another program's
        traffic on the port costs the least)."""
        d = self.dispatcher
        if data[:1] == b"/" and not data.startswith(_PREFIX):
            d.log.count("received", "OSC")
            d.reject("unknown", "OSC", data[:data.find(b"\x00")].decode("ascii", "replace"))
            return
        messages, bad = parse_packet(data)
        d.log.count("received", "OSC", len(messages) + bad)
        if bad:
            d.reject("malformed", "OSC", f"{bad} message(s) not OSC 1.0 with s, i, f")
        for msg in messages:
            cue = osc_cue(msg)
            if isinstance(cue, str):
                d.reject(cue, "OSC", f"{msg.address} {' '.join(map(str, msg.args))}".strip())
            else:
                d.dispatch(cue)

    def close(self) -> None:
        """Stop the thread and close the port (idempotent)."""
        thread, self._thread = self._thread, None
        with contextlib.suppress(OSError):
            self._wake_w.send(b"x")
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)
        for s in (self._sock, self._wake_r, self._wake_w):
            s.close()
