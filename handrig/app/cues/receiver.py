"""The OSC port: UDP datagrams read and parsed in a process of its own, which hands the run
only the cues and, a few times a second, the counts of what was no cue
(:class:`OscReceiver`; the child is :func:`relay_main`).

Why a process: a thread reading the port would share the interpreter lock with the
loop, and a controller sending a thousand messages a second (faders, or another
program's traffic on the port) raised the loop's p99 by hundreds of microseconds on a
loaded machine (docs/measurements.md, issue 40). The child parses every datagram; the
run's reader thread wakes only for a cue, a message worth a line in the log (the first
:data:`~handrig.app.cues.dispatch.IGNORED_SAID` of each kind) and the counts, at most
:data:`COUNTS_HZ` times a second. The port is bound in the run's process (so a port
that is taken is said before anything starts) and handed to the child.

The child's lines: ``ready``, then ``cue ACTION [ARG ...]``, ``reject WHY WHAT``,
``count WHAT N``
(``received``, ``unknown``, ``malformed``, ``released``). It ends when its stdin closes,
after its last counts.
"""

from __future__ import annotations

import contextlib
import os
import select
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator

from handrig.app.cues.dispatch import IGNORED_SAID, Cue, CueDispatcher, Rejected, osc_cue
from handrig.app.cues.osc import parse_packet
from handrig.config.cues import OSC_PREFIX
from handrig.errors import ConfigError
from handrig.realtime import helper_env, realtime_priority

MAX_DATAGRAM = 65535
COUNTS_HZ = 4.0
_PREFIX = OSC_PREFIX.encode("ascii")


def read_datagram(data: bytes) -> Iterator[Cue | tuple[Rejected, str]]:
    """A datagram's cues, and for each message that is none why and what it was. A
    message to an address outside ``/handrig/`` is unknown unparsed."""
    if data[:1] == b"/" and not data.startswith(_PREFIX):
        yield "unknown", data[:data.find(b"\x00")].decode("ascii", "replace")
        return
    messages, bad = parse_packet(data)
    if bad:
        yield "malformed", f"{bad} message(s) not OSC 1.0 with s, i, f"
    for msg in messages:
        cue = osc_cue(msg)
        if isinstance(cue, str):
            yield cue, f"{msg.address} {' '.join(map(str, msg.args))}".strip()
        else:
            yield cue


def messages_in(data: bytes) -> int:
    """How many messages (or elements that were none) a datagram counts as received."""
    if data[:1] == b"/" and not data.startswith(_PREFIX):
        return 1
    messages, bad = parse_packet(data)
    return len(messages) + bad


class OscReceiver:
    """Listens on ``(host, port)`` (UDP; port 0: any free one, see :attr:`port`) from
    :meth:`start` to :meth:`close`, through the relay process; every cue goes to
    ``dispatcher``, what is no cue is counted. ``flag`` names the setting in an error (a
    port taken, a host that is not this machine's); ``priority``: the reader thread's
    SCHED_FIFO priority (one below the loop's, as the view's feeder)."""

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
        self._proc: subprocess.Popen[str] | None = None
        self._thread: threading.Thread | None = None
        self.on_error: Callable[[str], None] = lambda text: None
        self.ready = threading.Event()
        """Set once the relay reads the port (datagrams before wait in its buffer)."""

    def start(self) -> OscReceiver:
        """The relay started on the port, and the thread reading its lines."""
        if self._proc is None:
            fd = self._sock.fileno()
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "handrig.app.cues.receiver", str(fd)],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, pass_fds=(fd,),
                env=helper_env(), start_new_session=True)  # a Ctrl-C is the run's alone;
            # the relay ends when its stdin closes (the run's end, or the run's death)
            self._thread = threading.Thread(target=self._run, name="handrig-osc-in",
                                            daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        proc = self._proc
        assert proc is not None and proc.stdout is not None
        with realtime_priority(self.priority):
            for line in proc.stdout:
                self.take_line(line.rstrip("\n"))
        if proc.wait() != 0:
            self.on_error(f"the OSC relay ended with status {proc.returncode}")

    def take_line(self, line: str) -> None:
        """One line of the relay: a cue acted on, a message that was none said, counts."""
        d = self.dispatcher
        kind, _, rest = line.partition(" ")
        if kind == "cue":
            words = rest.split(" ")
            d.dispatch(Cue(words[0], tuple(words[1:]), "OSC"))
        elif kind == "reject":
            why, _, what = rest.partition(" ")
            d.reject(why, "OSC", what)  # type: ignore[arg-type]
        elif kind == "count":
            what, _, n = rest.partition(" ")
            d.log.count(what, "OSC", int(n))
        elif kind == "ready":
            self.ready.set()

    def handle(self, data: bytes) -> None:
        """One datagram handled in this process, as the relay and this reader do it
        together (tests; the relay's own path)."""
        for line in _lines(data, {}, {}):
            self.take_line(line)

    def close(self) -> None:
        """The relay told to end (its last counts read), the port closed (idempotent)."""
        proc, thread = self._proc, self._thread
        self._proc = self._thread = None
        if proc is not None:
            with contextlib.suppress(OSError, ValueError):
                assert proc.stdin is not None
                proc.stdin.close()
            try:
                proc.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)
        self._sock.close()


def _lines(data: bytes, counts: dict[str, int], said: dict[str, int]) -> Iterator[str]:
    """The relay's lines for one datagram: cues and the first few of each kind of what
    was no cue at once; the rest added to ``counts`` (sent later, aggregated)."""
    counts["received"] = counts.get("received", 0) + messages_in(data)
    for item in read_datagram(data):
        if isinstance(item, Cue):
            yield "cue " + " ".join((item.action, *item.args))
            continue
        why, what = item
        said[why] = said.get(why, 0) + 1
        if said[why] <= IGNORED_SAID and why != "released":
            yield f"reject {why} {what.replace(chr(10), ' ')}"  # counted by the reader
        else:
            counts[why] = counts.get(why, 0) + 1
    if not counts.get("_deferred"):
        yield from _flush(counts)


def _flush(counts: dict[str, int]) -> Iterator[str]:
    for what in ("received", "unknown", "malformed", "released"):
        n = counts.pop(what, 0)
        if n:
            yield f"count {what} {n}"


def relay_main(fd: int) -> int:
    """The child: read the port ``fd``, write the lines, until stdin closes."""
    sock = socket.socket(fileno=fd)
    out = sys.stdout
    counts: dict[str, int] = {"_deferred": 1}
    said: dict[str, int] = {}
    period = 1.0 / COUNTS_HZ
    next_s = time.monotonic() + period
    out.write("ready\n")
    out.flush()
    while True:
        ready, _, _ = select.select([sock, sys.stdin], [], [],
                                    max(0.0, next_s - time.monotonic()))
        if sys.stdin in ready and not os.read(sys.stdin.fileno(), 1):
            break
        if sock in ready:
            for line in _lines(sock.recv(MAX_DATAGRAM), counts, said):
                out.write(line + "\n")
            out.flush()
        if time.monotonic() >= next_s:
            next_s = time.monotonic() + period
            lines = list(_flush(counts))
            if lines:
                out.write("\n".join(lines) + "\n")
                out.flush()
    lines = list(_flush(counts))
    if lines:
        out.write("\n".join(lines) + "\n")
    out.flush()
    return 0


if __name__ == "__main__":
    sys.exit(relay_main(int(sys.argv[1])))
