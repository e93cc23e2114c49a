"""The show's keys: single keys from a terminal, read without blocking.

Space relaxes or resumes, ``q`` stops (ease, then torque off), ``e`` is the e-stop
(torque off at once), ``r`` starts a take or stops it (:data:`SHOW_KEYS`); the callbacks
are the loop's and the session's.
"""

from __future__ import annotations

import contextlib
import os
import select
import termios
import threading
import tty
from collections.abc import Callable, Mapping
from types import TracebackType
from typing import Any

SHOW_KEYS: dict[str, str] = {
    " ": "relax/resume",
    "q": "stop (ease, torque off)",
    "e": "e-stop",
    "r": "record on/off",
}
"""The show's keys and what each does (the callbacks are the loop's)."""


class KeyReader:
    """Single keys from a terminal, read without blocking, each calling its callback.

    ``bindings``: key -> callable (e.g. ``{" ": toggle_relax, "q": stop, "e":
    estop}``, see :meth:`for_show`); letters match either case. Within ``with``
    (or between :meth:`open` and :meth:`close`) the terminal on ``fd`` is in
    cbreak mode: keys arrive one at a time and are not echoed, Ctrl-C still
    interrupts; the previous settings are restored on close, also after an
    error. :meth:`poll` handles what has arrived and never waits; :meth:`start`
    polls from a thread. Escape sequences (arrow keys) are ignored. A callback
    that raises is reported to ``on_error``; without one it is re-raised from
    :meth:`poll`, and the thread keeps it in :attr:`error` and stops reading.
    """

    def __init__(self, fd: int, bindings: Mapping[str, Callable[[], None]], *,
                 poll_s: float = 0.05,
                 on_error: Callable[[BaseException], None] | None = None) -> None:
        self.fd = fd
        self.bindings = {(k if len(k) == 1 and not k.isalpha() else k.lower()): v
                         for k, v in bindings.items()}
        self.poll_s = poll_s
        self.on_error = on_error
        self.pressed: list[str] = []  # every bound key handled, in order
        self.eof = False  # the terminal went away
        self.error: BaseException | None = None  # what stopped the thread
        self._saved: list[Any] | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @classmethod
    def for_show(cls, fd: int, *, toggle_relax: Callable[[], None], stop: Callable[[], None],
                 estop: Callable[[], None], record: Callable[[], None] | None = None,
                 **kwargs: Any) -> KeyReader:
        """The show's keys (:data:`SHOW_KEYS`): space, ``q``, ``e`` and (given ``record``,
        a new take or the end of one) ``r``."""
        keys = {" ": toggle_relax, "q": stop, "e": estop}
        if record is not None:
            keys["r"] = record
        return cls(fd, keys, **kwargs)

    def open(self) -> KeyReader:
        """Put the terminal in cbreak mode (nothing happens if ``fd`` is no terminal)."""
        if self._saved is None and os.isatty(self.fd):
            self._saved = termios.tcgetattr(self.fd)
            tty.setcbreak(self.fd, termios.TCSANOW)
        return self

    def close(self) -> None:
        """Stop the thread and restore the terminal. Idempotent."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        self._thread = None
        if self._saved is not None:
            with contextlib.suppress(termios.error, OSError):
                termios.tcsetattr(self.fd, termios.TCSADRAIN, self._saved)
            self._saved = None

    def __enter__(self) -> KeyReader:
        return self.open()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def poll(self, timeout_s: float = 0.0) -> int:
        """Handle the keys that arrived (waiting at most ``timeout_s`` for the first);
        returns how many bound keys were handled."""
        handled = 0
        wait = timeout_s
        while not self.eof:
            try:
                ready, _, _ = select.select([self.fd], [], [], wait)
            except (OSError, ValueError):
                self.eof = True
                break
            if not ready:
                break
            wait = 0.0
            try:
                data = os.read(self.fd, 64)
            except BlockingIOError:
                break
            except OSError:
                data = b""
            if not data:
                self.eof = True
                break
            handled += self._dispatch(data.decode("utf-8", errors="ignore"))
        return handled

    def _dispatch(self, text: str) -> int:
        handled = 0
        i = 0
        while i < len(text):
            ch = text[i]
            i += 1
            if ch == "\x1b":  # an escape sequence: skip to its final byte
                while i < len(text) and not (text[i].isalpha() or text[i] == "~"):
                    i += 1
                i += 1
                continue
            fn = self.bindings.get(ch.lower() if ch.isalpha() else ch)
            if fn is None:
                continue
            self.pressed.append(ch)
            handled += 1
            try:
                fn()
            except Exception as exc:
                if self.on_error is None:
                    raise
                self.on_error(exc)
        return handled

    def start(self) -> KeyReader:
        """Poll from a background thread until :meth:`close` (opens the terminal first)."""
        self.open()
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="handrig-keys",
                                            daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.is_set() and not self.eof:
            try:
                self.poll(self.poll_s)
            except Exception as exc:  # a callback failed and there is no on_error
                self.error = exc
                return
