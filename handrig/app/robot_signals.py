"""A stop signal that finds the program's main thread blocked still ends the block.

Python runs a signal's handler in the main thread only, between two bytecodes or
when a blocking call returns early with EINTR. A SIGTERM whose C-level handler runs
just before the main thread enters a blocking call (the time between Python's last
check and the system call: a ``time.sleep(60)`` right after a ``print``), or on
another thread of the process (the kernel may hand a process-directed signal to any
thread that does not block it), interrupts nothing: the main thread sleeps on, the
handler that would turn torque off waits with it, and the robot loop's thread keeps
driving the servos, so a process manager's SIGTERM did not end the program (a
clean-clone CI run at 00:19 on 2026-12-06 saw it: the main thread still in its
``time.sleep(60)`` 30 s after the SIGTERM, the loop thread at its fixed rate).

:class:`StopSignalWake` closes the gap inside a :class:`~handrig.app.robot_api.RobotHand`
block opened on the main thread: Python's wakeup descriptor
(:func:`signal.set_wakeup_fd`, written by the C-level handler on whatever thread
the signal lands) is a pipe that a thread of its own watches; when a stop signal
came and its handler has not run :data:`WAKE_GRACE_S` later, that thread
sends the signal to the main thread itself (:func:`signal.pthread_kill`), whose
blocking call then returns with EINTR and runs the handler: the block ends with
torque off. "Not yet handled" is told by the handler's own runs (the torque context's
handler, wrapped and counted), not by the block's end: a program whose handler ran and
that is busy cleaning up (a ``finally`` that takes a while) is not sent it again. A
wakeup descriptor the program had set (asyncio's) still gets every byte. The threads
handrig starts block the stop signals (:func:`signals_blocked`), so the kernel hands
them to a thread of the program's.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import threading
import time
from collections.abc import Callable, Iterator
from types import FrameType

from handrig.devices.servo.torque import STOP_SIGNALS

WAKE_GRACE_S = 0.5
"""How long a stop signal's handler may take to run before the main thread is sent the
signal again (a main thread that took it runs the handler at once)."""
WAKE_POLL_S = 0.005


@contextlib.contextmanager
def signals_blocked() -> Iterator[None]:
    """The stop signals blocked in this thread meanwhile: a thread started inside
    inherits the mask and never takes one (a signal sent meanwhile waits, not lost)."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


class StopSignalWake:
    """The main thread woken when a stop signal left it blocked (module docstring).

    :meth:`start` on the main thread once the torque context has installed its handlers
    (elsewhere no handler runs, and nothing is watched): each stop signal's handler is
    wrapped so that its runs are counted; a stop signal whose handler has not run
    :data:`WAKE_GRACE_S` after it came, while the wrapper is still the handler (the
    torque context not yet over), is sent to the main thread. ``log``: one line then.
    :meth:`stop` from the thread that started it."""

    def __init__(self, log: Callable[[str], None]) -> None:
        self._log = log
        self._thread: threading.Thread | None = None
        self._fds: tuple[int, int] = (-1, -1)  # the wakeup pipe: read end, write end
        self._quit: tuple[int, int] = (-1, -1)  # a pipe that ends the watching thread
        self._old_fd = -1  # the program's wakeup descriptor, given every byte too
        self._wrappers: dict[int, Callable[[int, FrameType | None], object]] = {}
        self._came: dict[int, int] = {}  # by signal: how many the descriptor said came
        self._ran: dict[int, int] = {}  # ... and how many times its handler ran
        self.woken = 0
        """Stop signals the main thread had to be sent again."""

    def start(self) -> None:
        if threading.current_thread() is not threading.main_thread():
            return
        for sig in STOP_SIGNALS:
            handler = signal.getsignal(sig)
            if callable(handler):
                self._wrappers[sig] = wrapper = self._counted(handler)
                signal.signal(sig, wrapper)
        self._fds, self._quit = os.pipe(), os.pipe()
        for fd in (*self._fds, *self._quit):
            os.set_blocking(fd, False)
        self._old_fd = signal.set_wakeup_fd(self._fds[1], warn_on_full_buffer=False)
        self._thread = threading.Thread(target=self._watch, args=(threading.main_thread(),),
                                        name="handrig-robot-signals", daemon=True)
        with signals_blocked():
            self._thread.start()

    def _counted(self, handler: Callable[[int, FrameType | None], object]
                 ) -> Callable[[int, FrameType | None], object]:
        def counted(signum: int, frame: FrameType | None) -> object:
            self._ran[signum] = self._ran.get(signum, 0) + 1
            return handler(signum, frame)
        return counted

    def _handler_due(self, sig: int) -> bool:
        """A signal came whose handler has not run, while its wrapper is installed."""
        return (self._ran.get(sig, 0) < self._came.get(sig, 0)
                and signal.getsignal(sig) is self._wrappers.get(sig))

    def _watch(self, main: threading.Thread) -> None:
        wake_r, quit_r = self._fds[0], self._quit[0]
        while True:
            ready, _, _ = select.select([wake_r, quit_r], [], [])
            if quit_r in ready:
                return
            try:
                got = os.read(wake_r, 512)
            except BlockingIOError:
                continue
            if self._old_fd >= 0:
                with contextlib.suppress(OSError):
                    os.write(self._old_fd, got)
            stops = [s for s in got if s in self._wrappers]
            for sig in stops:
                self._came[sig] = self._came.get(sig, 0) + 1
            for sig in dict.fromkeys(stops):
                end = time.monotonic() + WAKE_GRACE_S
                while self._handler_due(sig) and time.monotonic() < end:
                    time.sleep(WAKE_POLL_S)
                ident = main.ident
                if not self._handler_due(sig) or ident is None or not main.is_alive():
                    continue
                self.woken += 1
                self._log(f"{signal.Signals(sig).name} came while the program's main thread "
                          "was blocked: sending it to the main thread, which ends the block")
                with contextlib.suppress(OSError, ValueError):
                    signal.pthread_kill(ident, sig)

    def stop(self) -> None:
        thread, self._thread = self._thread, None
        if thread is None:
            return
        os.write(self._quit[1], b"x")
        thread.join(timeout=2.0)
        try:
            current = signal.set_wakeup_fd(self._old_fd)
        except ValueError:  # not the main thread: the pipe stays open (the C-level
            return          # handler writes to it), nothing else can be restored
        if current != self._fds[1]:  # the program set its own meanwhile: kept
            signal.set_wakeup_fd(current)
        if not thread.is_alive():
            for fd in (*self._fds, *self._quit):
                os.close(fd)
        self._fds = self._quit = (-1, -1)
