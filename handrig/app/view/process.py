"""The view in a process of its own, so that its work never holds the loop's GIL.

The run's process keeps one small thread (the feeder): 60 times a second it takes
``rig.telemetry.latest()`` and, when it is new, sends it pickled (a few KB, tens of
microseconds) down the child's stdin. The feeder shares the interpreter lock with the
loop: were it preempted while holding the lock (by a browser on the same machine),
the loop would wait for it; so where the loop runs under SCHED_FIFO the feeder does
too, one priority below (only the loop preempts it, and it holds the lock for
microseconds). The child stays off the loop's CPU (``HANDRIG_CPUS``, as the
emulators) at nice 10. The child (``python -m
handrig.app.view.process``) builds the models, serves the page (:class:`ViewServer`)
and does the kinematics and the JSON there. A button press comes back as one line
on the child's stdout, read by a second thread that calls the rig at once.

Messages, parent to child: a 4-byte big-endian length, then a pickle: first the
setup (address, rig config, title, actions), then snapshots. Child to parent, lines:
``ready PORT TOKEN|-``, ``error MESSAGE``, ``action NAME``, ``stats JSON`` (at exit).
The child ends when its stdin closes.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import pickle
import struct
import subprocess
import sys
import threading
from collections.abc import Mapping
from typing import IO, TYPE_CHECKING, Any

from handrig.app.view.encode import HandsSnapshot
from handrig.errors import ConfigError
from handrig.realtime import apply_cpus_from_env, helper_env, realtime_priority

if TYPE_CHECKING:
    from handrig.app.view.server import HandsControls, RigControls
    from handrig.config.rig import RigConfig
    from handrig.loop.telemetry import LoopSnapshot

FEED_HZ = 60.0  # twice the loop's publication rate: each snapshot is sent soon after it is made
CHILD_NICE = 10  # the view yields the CPU to the run, its emulators and everything else
START_TIMEOUT_S = 120.0


def _write(stream: IO[bytes], obj: object) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(struct.pack(">I", len(data)) + data)
    stream.flush()


def _read(stream: IO[bytes]) -> Any:
    head = stream.read(4)
    if len(head) < 4:
        raise EOFError
    (size,) = struct.unpack(">I", head)
    data = stream.read(size)
    if len(data) < size:
        raise EOFError
    return pickle.loads(data)


class ViewProcess:
    """``--view ADDRESS`` served by a child process for the rig ``rig_config``.
    :meth:`start` raises ConfigError naming the port when it is taken; :meth:`attach`
    feeds it a rig's telemetry; :meth:`close` ends it (idempotent)."""

    def __init__(self, address: str, rig_config: RigConfig, *, title: str = "handrig",
                 flag: str = "--view") -> None:
        self.address, self.rig_config, self.title, self.flag = address, rig_config, title, flag
        self.url = ""
        self.port = 0
        self.stats: dict[str, Any] = {}
        self.actions: list[str] = []
        self._proc: subprocess.Popen[bytes] | None = None
        self._controls: RigControls | None = None
        self._stop = threading.Event()
        self._feeder: threading.Thread | None = None
        self._reader: threading.Thread | None = None
        self._first_line: list[str] = []
        self._ready = threading.Event()

    @property
    def pid(self) -> int | None:
        return self._proc.pid if self._proc is not None else None

    @property
    def feeder_thread_id(self) -> int | None:
        return self._feeder.native_id if self._feeder is not None else None

    def start(self) -> ViewProcess:
        env = {**helper_env(), "PYTHONUNBUFFERED": "1"}  # off the loop's CPU
        # a session of its own: a Ctrl-C at the terminal goes to the run, which eases the
        # puppet down and then closes the view (the child ends when its stdin closes)
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "handrig.app.view.process"], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, env=env, start_new_session=True)
        assert self._proc.stdin is not None  # for mypy: PIPE was asked for
        _write(self._proc.stdin, {"address": self.address, "rig_config": self.rig_config,
                                  "title": self.title})
        self._reader = threading.Thread(target=self._read_child, name="handrig-view-reader",
                                        daemon=True)
        self._reader.start()
        if not self._ready.wait(START_TIMEOUT_S) or not self._first_line:
            self.close()
            raise ConfigError("the view's process did not start", key=self.flag,
                              value=self.address, allowed="see the lines above")
        word, _, rest = self._first_line[0].partition(" ")
        if word != "ready":
            self.close()
            try:
                why = json.loads(rest)
            except ValueError:
                why = {"detail": rest or "the view's process failed", "allowed": ""}
            raise ConfigError(why["detail"], key=self.flag, value=self.address,
                              allowed=why["allowed"] or None)
        port, _, url = rest.partition(" ")
        self.port, self.url = int(port), url
        return self

    def _read_child(self) -> None:
        proc = self._proc
        assert proc is not None and proc.stdout is not None
        for raw in proc.stdout:
            line = raw.decode(errors="replace").rstrip("\n")
            word, _, rest = line.partition(" ")
            if not self._ready.is_set():
                self._first_line.append(line)
                self._ready.set()
            elif word == "action":
                self._act(rest)
            elif word == "stats":
                with contextlib.suppress(ValueError):
                    self.stats = json.loads(rest)
        self._ready.set()  # the child ended before it was ready

    def _act(self, action: str) -> None:
        controls = self._controls
        if controls is None:
            return
        self.actions.append(action)
        if action == "estop":
            controls.estop("e-stop button (view)")
        elif action == "stop":
            controls.request_stop("stop button (view)")
        elif action == "relax":
            controls.toggle_relax()

    def attach(self, source: Any, controls: RigControls | None = None) -> None:
        """Feed ``source()`` (``rig.telemetry.latest``) to the page; the buttons call
        ``controls`` (the rig)."""
        self._controls = controls
        if self._feeder is None:
            self._feeder = threading.Thread(target=self._feed, args=(source,),
                                            name="handrig-view-feeder", daemon=True)
            self._feeder.start()

    def attach_hands(self, rigs: Mapping[str, Any], controls: HandsControls) -> None:
        """:meth:`attach` for a session's loops: ``rigs`` by hand (``"ri"``, ``"le"``;
        ``""`` for one loop driving the whole rig), each loop's snapshot read by the same
        feeder (a :class:`HandsSnapshot` once every hand has published one); the buttons
        call ``controls``, which act on every hand as the keys do; the cues the page
        lists are ``controls.recent_cues()``."""
        latest = {h: rig.telemetry.latest for h, rig in rigs.items()}

        def every() -> HandsSnapshot | None:
            snaps = {h: read() for h, read in latest.items()}
            if any(s is None for s in snaps.values()):
                return None
            return HandsSnapshot(snaps, controls.recent_cues())
        self.attach(every, controls)

    def feeder_priority(self) -> int:
        """The feeder's SCHED_FIFO priority: one below the loop's (0: normal, when the
        loop's is 0 or 1)."""
        loop = self.rig_config.loop.realtime_priority
        return loop - 1 if loop > 1 else 0

    def _feed(self, source: Any) -> None:
        with realtime_priority(self.feeder_priority()):
            self._feed_loop(source)

    def _feed_loop(self, source: Any) -> None:
        proc = self._proc
        assert proc is not None and proc.stdin is not None
        last = -1
        period = 1.0 / FEED_HZ
        while not self._stop.wait(period):
            snap: LoopSnapshot | HandsSnapshot | None = source()
            if snap is None or snap.seq == last:
                continue
            last = snap.seq
            try:
                _write(proc.stdin, snap)
            except (OSError, ValueError):  # the child is gone: the run goes on without it
                return

    def close(self) -> None:
        self._stop.set()
        if self._feeder is not None:
            self._feeder.join(timeout=2.0)
        proc = self._proc
        if proc is None:
            return
        if self._feeder is not None and self._feeder.is_alive():
            # the feeder is stuck writing to a child that stopped reading: closing the
            # pipe would wait for it, so the child goes first
            proc.kill()
        with contextlib.suppress(OSError, ValueError):
            if proc.stdin is not None:
                proc.stdin.close()
        try:
            proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if self._reader is not None:
            self._reader.join(timeout=2.0)
        self._proc = None

    def __enter__(self) -> ViewProcess:
        return self.start() if self._proc is None else self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _Relay:
    """The child's side of the buttons: each press is a line to the parent."""

    def __init__(self, out: IO[str]) -> None:
        self.out = out
        self.lock = threading.Lock()

    def _send(self, action: str) -> None:
        with self.lock, contextlib.suppress(OSError, ValueError):
            self.out.write(f"action {action}\n")
            self.out.flush()

    def toggle_relax(self) -> None:
        self._send("relax")

    def request_stop(self, reason: str = "") -> None:
        self._send("stop")

    def estop(self, reason: str = "") -> None:
        self._send("estop")


def child_main() -> int:
    """The child: serve until stdin closes."""
    from handrig.app.view import build_server

    stdin, out = sys.stdin.buffer, sys.stdout
    sys.stdout = sys.stderr  # nothing else may write on the protocol's stream
    apply_cpus_from_env()
    os.nice(CHILD_NICE)
    setup = _read(stdin)
    try:
        server = build_server(setup["address"], setup["rig_config"], title=setup["title"])
        server.start()
    except Exception as exc:  # reported to the parent, which raises it
        detail, allowed = ((exc.detail, exc.allowed or "") if isinstance(exc, ConfigError)
                           else (f"{type(exc).__name__}: {exc}", ""))
        out.write(f"error {json.dumps({'detail': detail, 'allowed': allowed})}\n")
        out.flush()
        return 1
    latest: list[LoopSnapshot | HandsSnapshot | None] = [None]
    server.attach(lambda: latest[0], _Relay(out))
    out.write(f"ready {server.port} {server.url}\n")
    out.flush()
    try:
        while True:
            latest[0] = _read(stdin)
    except (EOFError, OSError, pickle.UnpicklingError):
        pass
    finally:
        server.close()
        stats = dataclasses.asdict(server.stats)
        with contextlib.suppress(OSError, ValueError):
            out.write(f"stats {json.dumps(stats)}\n")
            out.flush()
    return 0


if __name__ == "__main__":
    sys.exit(child_main())
