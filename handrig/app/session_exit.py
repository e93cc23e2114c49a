"""How a session ends: the exit signals, and torque read back once it is off.

Every way a user ends a run is handled alike (:class:`ExitSignals`): Ctrl-C
(SIGINT), SIGTERM, SIGHUP (the terminal or the SSH session closed) and SIGQUIT.
Before the rig is ready a signal unwinds (devices closed, emulators stopped,
torque never on). While it runs, the first signal eases to the relaxed pose and
stops, a second stops at the next cycle, a third raises at once (torque still
goes off on the way out). During torque-off and shutdown signals are counted and
ignored.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable
from types import FrameType, TracebackType
from typing import Any

from handrig.devices.servo.bus import ServoBus
from handrig.errors import SafetyStop

EXIT_SIGNALS: tuple[signal.Signals, ...] = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT")
    if hasattr(signal, name))


READBACK_BUDGET_S = 1.5  # reading torque back at exit: a silent servo costs 0.4 s


def torque_is_off(bus: ServoBus) -> bool | None:
    """Torque read back from every servo (:meth:`ServoBus.confirm_torque_off`): True if
    all are off, None if one could not be read, False if one is still on."""
    return bus.confirm_torque_off(READBACK_BUDGET_S)[0]


class ExitSignals:
    """SIGINT, SIGTERM, SIGHUP and SIGQUIT, handled alike for one session (main thread
    only; elsewhere nothing is installed). See the module docstring for what each
    phase does with them: :meth:`arm` when the rig can be asked to stop, :meth:`disarm`
    when the loop is over."""

    def __init__(self) -> None:
        self.received = 0
        self.last = ""
        self._stop: Callable[[str], None] | None = None
        self._ignoring = False
        self._while_armed = 0
        self._saved: dict[int, Any] = {}

    def __enter__(self) -> ExitSignals:
        if threading.current_thread() is threading.main_thread():
            for sig in EXIT_SIGNALS:
                self._saved[sig] = signal.signal(sig, self._handler)
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        for sig, old in self._saved.items():
            signal.signal(sig, old)
        self._saved.clear()

    def arm(self, stop: Callable[[str], None]) -> None:
        """From now on a signal calls ``stop(reason)`` (twice at most), then raises."""
        self._stop = stop

    def disarm(self) -> None:
        """The loop is over: torque-off and shutdown must finish; signals are ignored."""
        self._stop = None
        self._ignoring = True

    def _handler(self, signum: int, frame: FrameType | None) -> None:
        name = signal.Signals(signum).name
        self.received += 1
        self.last = name
        if self._ignoring:
            return
        if self._stop is None:
            raise SafetyStop(f"{name} received before the rig started: stopped, torque was off")
        self._while_armed += 1
        if self._while_armed <= 2:
            self._stop(f"{name} received")
            return
        raise SafetyStop(f"{name} received again: stopping the servos with torque off")


def is_terminal(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, OSError, ValueError):
        return False


def never_raises(log: Callable[[str], None]) -> Callable[[str], None]:
    """``log`` that drops a line it cannot write (the terminal closed: SIGHUP)."""
    def safe(text: str) -> None:
        with contextlib.suppress(OSError, ValueError):
            log(text)
    return safe
