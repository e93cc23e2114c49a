"""The emulated bus's line: its end of a pty, the client's baud, the bus thread's timing.

The emulator holds only the master side of the pty. The slave side
(``port_path``, e.g. ``/dev/pts/7``) is closed as soon as its name is known, so
the port looks like a real adapter's: nobody holds it until a client opens it
(a client that checks whether a port is busy, as GELLO's driver does with
``fuser``, finds it free), and a client may close it and open it again. While
no client holds it, the master side reads EIO and polls POLLHUP; the line
reports that as ``client_open = False`` and counts each new opening in
``sessions``.

The client's baud is read from the pty's termios (a pty carries the setting the
client made, though it delivers bytes at once whatever it is).
"""

from __future__ import annotations

import errno
import os
import select
import termios
import time
import tty

from handrig.realtime import LOOP_TIMER_SLACK_NS, timer_slack_ns

try:  # the termios speed without building tcgetattr's lists (sim/_dxl_c.c, where built)
    from sim._dxl_c import line_baud as _line_speed
except ImportError:
    _line_speed = None  # type: ignore[assignment]

BITS_PER_BYTE = 10  # start + 8 data + stop
# Replies are timed by sleeping, then spinning for the last SPIN_S (with the thread's
# timer slack cut to 1 us, Linux sleeps overshoot by tens of microseconds).
SPIN_S = 60e-6
# SCHED_FIFO priority of the bus thread when ``realtime`` (low: above normal tasks only).
REALTIME_PRIORITY = 10
# The physics thread's, below the bus thread's: a thread that shares the bus thread's
# interpreter must not be preempted by ordinary work while it holds the GIL (the bus
# thread would wait for it: a priority inversion of milliseconds on a loaded machine).
PHYSICS_PRIORITY = 5
# While no client holds the port, the line looks again this often.
NO_CLIENT_POLL_S = 0.005
DEFAULT_BAUD = 1_000_000


def tighten_timer_slack() -> None:
    """Timer slack of 1 us for the calling thread (Linux; no-op elsewhere)."""
    timer_slack_ns(LOOP_TIMER_SLACK_NS)


def try_realtime(priority: int = REALTIME_PRIORITY) -> bool:
    """SCHED_FIFO for the calling thread where allowed; False when refused or unsupported.

    On a loaded machine a normal thread wakes late from its sleeps, and its replies
    leave late (docs/measurements.md)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError):
        return False
    return True


def _baud_table() -> dict[int, int]:
    out: dict[int, int] = {}
    for name in dir(termios):
        if name.startswith("B") and name[1:].isdigit():
            out[getattr(termios, name)] = int(name[1:])
    return out


BAUD_OF_SPEED = _baud_table()


class PtyLine:
    """The master side of a pty; ``path`` is the slave side a client opens."""

    def __init__(self) -> None:
        self.fd = -1
        self.path = ""
        self.client_open = False
        self.sessions = 0
        """How many times a client opened the port (noticed at its first poll)."""
        self.closes = 0
        """How many times a client that held the port let it go."""
        self._poll = select.poll()

    def open(self) -> str:
        """Create the pty, keep only its master side; returns the slave side's path."""
        master, slave = os.openpty()
        tty.setraw(master)
        tty.setraw(slave)
        self.path = os.ttyname(slave)
        os.close(slave)  # the emulator holds no end a client opens
        os.set_blocking(master, False)
        self.fd = master
        self._poll = select.poll()
        self._poll.register(master, select.POLLIN | select.POLLHUP | select.POLLERR)
        self.client_open = False
        return self.path

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
        self.fd = -1
        self.client_open = False

    def baud(self) -> int:
        """The baud rate the client set on the port (termios), 1 Mbps if unknown."""
        try:
            speed = _line_speed(self.fd) if _line_speed is not None \
                else termios.tcgetattr(self.fd)[5]
        except (termios.error, OSError):
            return DEFAULT_BAUD
        return BAUD_OF_SPEED.get(speed, DEFAULT_BAUD) or DEFAULT_BAUD

    def wait(self, timeout_s: float) -> tuple[bytes | None, bool]:
        """Wait up to ``timeout_s`` for bytes: ``(data or None, closed_now)``.

        ``closed_now`` is True once when a client that held the port let it go.
        With no client, returns after ``NO_CLIENT_POLL_S`` at most, with no data."""
        events = self._poll.poll(timeout_s * 1000.0)
        if not events:
            self._opened()
            return None, False
        revents = events[0][1]
        try:
            data = os.read(self.fd, 65536)
        except BlockingIOError:
            data = b""
        except OSError as exc:
            if exc.errno != errno.EIO:
                raise
            data = b""
            revents |= select.POLLHUP
        if data:
            self._opened()
            return data, False
        if revents & select.POLLHUP:
            was_open = self.client_open
            if was_open:
                self.closes += 1
            self.client_open = False
            time.sleep(NO_CLIENT_POLL_S)  # poll reports HUP at once while no client holds it
            return None, was_open
        return None, False

    def _opened(self) -> None:
        if not self.client_open:
            self.client_open = True
            self.sessions += 1

    def write(self, data: bytes) -> None:
        """Put bytes on the line; lost (as on a real wire) when no client holds the port."""
        try:
            os.write(self.fd, data)
        except OSError as exc:
            if exc.errno not in (errno.EIO, errno.EAGAIN):
                raise
