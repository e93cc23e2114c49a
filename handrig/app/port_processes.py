"""Helper processes that serve a port: the emulators a simulated rig runs on.

Each is ``python -m MODULE ARGV`` (a handrig subcommand by default: ``handrig
sim-bus``, ``handrig sim-glove``) that prints ``port: PATH`` as its first line.
It runs in its own session (a Ctrl-C in the terminal reaches the rig alone: the
rig eases, turns torque off, and only then stops them) and gets SIGTERM if this
process dies. Starting one and waiting for its port are two steps
(:class:`PortProcess`), so a run that needs several starts them all first and
their start-ups overlap (:class:`StartedEmulators`).
"""

from __future__ import annotations

import contextlib
import selectors
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from types import TracebackType

from handrig.errors import DeviceError
from handrig.realtime import helper_env


def _die_with_parent() -> Callable[[], None] | None:
    """A ``preexec_fn`` that has the child get SIGTERM when this process dies (Linux
    ``PR_SET_PDEATHSIG``): an emulator in its own session would otherwise outlive a
    rig that was killed. None where there is no such thing."""
    try:
        import ctypes

        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    pr_set_pdeathsig = 1

    def preexec() -> None:
        prctl(pr_set_pdeathsig, int(signal.SIGTERM), 0, 0, 0)
    return preexec


class PortProcess:
    """``python -m module ARGV`` started (not yet waited for); :meth:`port` waits for
    its ``port: PATH`` line. A context manager: on exit (or :meth:`stop`) it gets
    SIGTERM and is waited for, so the emulator shuts down cleanly."""

    def __init__(self, argv: Sequence[str], what: str, *, module: str = "handrig.cli",
                 cwd: str | Path | None = None) -> None:
        self.argv = tuple(argv)
        self.what = what
        cmd = [sys.executable, "-m", module, *argv]
        env = helper_env()  # off the loop's CPU
        self.proc: subprocess.Popen[str] = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
            cwd=cwd, start_new_session=True, preexec_fn=_die_with_parent())
        self._port: str | None = None

    def port(self, timeout_s: float = 30.0) -> str:
        """The port the process serves, waited for up to ``timeout_s`` (once; later
        calls return it at once). DeviceError with what it printed, the process killed,
        when it does not say ``port: PATH`` first."""
        if self._port is not None:
            return self._port
        proc = self.proc
        assert proc.stdout is not None
        sel = selectors.DefaultSelector()
        sel.register(proc.stdout, selectors.EVENT_READ)
        line = ""
        if sel.select(timeout_s):
            line = proc.stdout.readline().strip()
        sel.close()
        if not line.startswith("port: "):
            proc.kill()
            _, err = proc.communicate(timeout=5)
            raise DeviceError(
                f"{self.what} did not start ({' '.join(self.argv)}): "
                f"{(line + ' ' + err).strip()[-400:] or 'no output'}"
            )
        self._port = line.removeprefix("port: ")
        return self._port

    def stop(self) -> None:
        """SIGTERM and wait (SIGKILL after 10 s); nothing when it has ended.

        The pipes stay open: callers read what the stopped process said afterwards
        (the emulator's counts and warnings), so this does not use
        :func:`stop_process`, whose communicate() consumes and closes them."""
        proc = self.proc
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()

    def __enter__(self) -> PortProcess:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()


@contextlib.contextmanager
def port_process(argv: Sequence[str], what: str, timeout_s: float = 30.0, *,
                 module: str = "handrig.cli", cwd: str | Path | None = None
                 ) -> Iterator[tuple[subprocess.Popen[str], str]]:
    """Start ``python -m module ARGV`` (a handrig subcommand by default) that prints
    ``port: PATH`` first, and wait for its port; stop it on exit.

    Yields the process and the port path (:class:`PortProcess`)."""
    with PortProcess(argv, what, module=module, cwd=cwd) as started:
        yield started.proc, started.port(timeout_s)


def stop_process(proc: subprocess.Popen[str]) -> str:
    """SIGTERM a port process, wait, and return what it printed after its port line."""
    if proc.poll() is None:
        proc.terminate()
    try:
        out, err = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
    return (out or "") + (err or "")


SIM_BUS = "the simulated servo bus (handrig sim-bus)"


def sim_bus_argv(rig_file: str | Path, hand: str | None = None, *, wire_timing: bool = True,
                 viewer: bool = False, faults: str = "") -> list[str]:
    """The ``handrig sim-bus`` arguments for the rig file ``rig_file`` (``hand``: one
    hand's servos of a two-hand rig), as :func:`handrig.app.factory.servo_bus` runs it."""
    argv = ["sim-bus", "--rig", str(rig_file)]
    if hand is not None:
        argv += ["--hand", hand]
    if wire_timing:
        argv.append("--wire-timing")
    if viewer:
        argv.append("--viewer")
    if faults:
        argv += ["--faults", faults]
    return argv


class StartedEmulators:
    """Emulators a run starts ahead of the step that uses them, so that their
    start-ups overlap (``handrig demo`` starts the simulated bus, then the glove, and
    waits for the glove's port while the bus builds its MuJoCo puppet).

    :meth:`start` starts one; :meth:`take` hands it, by its argv, to the step that
    needs it (which then owns it and stops it); on exit every one not taken is
    stopped. Keyed by the exact argv: a step that wants another emulator than the one
    started (another rig, other flags) takes none and starts its own."""

    def __init__(self) -> None:
        self._waiting: dict[tuple[str, ...], PortProcess] = {}

    def start(self, argv: Sequence[str], what: str) -> PortProcess:
        """Start ``handrig ARGV`` now; a second start of the same argv returns the first."""
        key = tuple(argv)
        if key not in self._waiting:
            self._waiting[key] = PortProcess(argv, what)
        return self._waiting[key]

    def take(self, argv: Sequence[str]) -> PortProcess | None:
        """The emulator started with exactly ``argv``, now the caller's; None if none."""
        return self._waiting.pop(tuple(argv), None)

    def close(self) -> None:
        """Stop every emulator started and not taken."""
        while self._waiting:
            _, started = self._waiting.popitem()
            started.stop()

    def __enter__(self) -> StartedEmulators:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
