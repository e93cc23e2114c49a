"""``handrig record glove``: a glove take with no rig, the glove read until time is up.

The glove is opened as ``handrig run`` opens it (:func:`handrig.app.factory.open_glove`)
and read as the loop reads it: blocking on its port and pumping what arrived (a replay:
sleeping until its next frame is due). Every good frame goes to a
:class:`~handrig.outputs.glove_take.GloveTake` through the glove's tap. SIGINT, SIGTERM
and SIGHUP end the take cleanly (the file finished and named); so does the end of a
replayed recording.
"""

from __future__ import annotations

import math
import select
import signal
import threading
from pathlib import Path
from types import FrameType
from typing import Any

from handrig.app import factory, parts
from handrig.app.takes import check_glove_take_path, open_glove_take
from handrig.clock import MonotonicClock
from handrig.devices.glove_calibration import load_glove_config

WAIT_S = 0.05  # the longest a wait for the port lasts before the time is checked again
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def record_glove_take(out: str, *, glove: str | None = None,
                      glove_file: str | None = None, seconds: float | None = None
                      ) -> dict[str, Any]:
    """Record the glove ``glove`` (None: the glove file's port) to ``out`` for ``seconds``
    (None: until a signal); returns what was done. ConfigError/DataError naming the flag
    or file before anything is opened."""
    check_glove_take_path(out, "OUT")
    cfg_path = Path(glove_file) if glove_file else None
    cfg = load_glove_config(cfg_path)
    spec = parts.glove_spec(glove, cfg, cfg_path)
    clock = MonotonicClock()
    stopped_by = [""]

    def stop(signum: int, frame: FrameType | None) -> None:
        stopped_by[0] = signal.Signals(signum).name

    saved = {}
    if threading.current_thread() is threading.main_thread():
        saved = {sig: signal.signal(sig, stop) for sig in STOP_SIGNALS}
    try:
        with factory.open_glove(spec, cfg, clock, cfg_path) as source:
            take = open_glove_take(out, source, cfg, source=spec)
            try:
                start = clock.now()
                end = math.inf if seconds is None else start + seconds
                while not stopped_by[0] and clock.now() < end:
                    _read_some(source, clock, min(end, clock.now() + WAIT_S))
                    take.format_pending()
                    if source.next_due_s() == math.inf:  # a replay that has ended
                        break
            finally:
                take.close()
            stats = source.stats()
    finally:
        for sig, old in saved.items():
            signal.signal(sig, old)
    return {"out": str(take.path), "glove": spec, "frames": take.frames_written,
            "duration_s": round(take.duration_s, 6), "bytes": take.bytes_written,
            "errors": stats.errors, "frames_dropped": take.frames_dropped,
            "stopped_by": stopped_by[0], "error": take.error}


def _read_some(source: Any, clock: MonotonicClock, until_s: float) -> None:
    """Wait for the glove until ``until_s`` and take what came (a port: pumped; a replay:
    each frame due by then)."""
    fd = source.fileno()
    if fd is not None:
        left = until_s - clock.now()
        try:
            ready, _, _ = select.select([fd], [], [], max(0.0, left))
        except (OSError, ValueError):  # the port went away: the glove says so, reopens
            clock.sleep_until(until_s)
            return
        if ready:
            source.pump()
        source.latest()
        return
    due = source.next_due_s()
    if due is None:  # a port that is being reopened: its pump does that
        source.pump()
        clock.sleep_until(until_s)
        source.latest()
        return
    clock.sleep_until(min(due, until_s))
    while source.has_behind():
        source.take_behind()
    source.latest()
