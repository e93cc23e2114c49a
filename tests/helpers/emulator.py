"""The bus emulator (``handrig sim-bus``) in a process of its own, on a pty.

:func:`start_sim_bus` starts it with the given flags and yields it once it has said
its port; on the way out it is resumed (a test may have stopped it with SIGSTOP),
asked to end with SIGTERM and killed if it has not within 10 s. The ``sim_bus``
fixture of tests/conftest.py is this with the flags of the test's
``@pytest.mark.sim_bus(...)`` marker.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

CLI = (sys.executable, "-m", "handrig.cli")


@dataclass(frozen=True)
class SimBusProcess:
    """A running emulator: its process (stdout after the port line, and stderr when
    asked for, are the test's to read) and the pty path a client opens."""

    proc: subprocess.Popen[str]
    port: str


@contextmanager
def start_sim_bus(*flags: str, stderr: int = subprocess.DEVNULL,
                  env: dict[str, str] | None = None) -> Iterator[SimBusProcess]:
    """``handrig sim-bus FLAGS`` until the block ends. ``stderr``: ``subprocess.PIPE``
    to read what the emulator says (its counts at exit)."""
    proc = subprocess.Popen([*CLI, "sim-bus", *flags], stdout=subprocess.PIPE,
                            stderr=stderr, text=True, env=env, start_new_session=True)
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()
        if not first.startswith("port: /dev/"):
            said = proc.stderr.read() if proc.stderr is not None else ""
            raise AssertionError(f"sim-bus {' '.join(flags)} said {first!r}, not its port"
                                 f"{': ' + said if said else ''}")
        yield SimBusProcess(proc, first.split()[1])
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGCONT)
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
