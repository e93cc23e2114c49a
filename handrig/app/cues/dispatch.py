"""Cues to actions: what an OSC message or a mapped MIDI message asks for, done as the
show's key or button does it, counted and written down as an event naming its source.

:func:`osc_cue` reads an OSC message as a :class:`Cue` (or says why not: an unknown
address, malformed arguments, a button's release); :class:`CueDispatcher` acts on cues
through :class:`CueTargets` (the session's controls, the cue takes, the layers) from
the receivers' threads, one cue at a time, and keeps a :class:`CueLog`: the counts the
summary shows, and the last few cues, with their source, for the panel and the view.
Nothing here runs on the loop's thread: the controls only leave a request the loop
takes between cycles.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

from handrig.app.cues.osc import OscMessage
from handrig.clock import Clock
from handrig.config.cues import CUE_ACTIONS, OSC_PREFIX
from handrig.errors import HandrigError

Rejected = Literal["unknown", "malformed", "released", "unmapped"]
"""Why a message is no cue: an address outside the vocabulary, arguments the action does
not take, a MIDI message the show file does not map, or a button's release (an argument
0 to an action without arguments: a surface's button sends 1 pressed, 0 let go)."""

COUNTS = ("received", "acted", "refused", "unknown", "malformed", "unmapped", "released")
"""What :class:`CueLog` counts: every message received; the cues acted on, and those
refused (a take that exists, a take not in the show ...); unknown OSC addresses, malformed
OSC packets or arguments, MIDI notes and controllers the show file does not map, and
releases (ignored)."""


@dataclass(frozen=True, slots=True)
class Cue:
    """One action asked for, its arguments and where it came from (``"OSC"``, ``"MIDI"``)."""

    action: str
    args: tuple[str, ...] = ()
    source: str = "OSC"

    def label(self) -> str:
        """``"play intro (OSC)"``: how the summary and the panel name it."""
        return " ".join((self.action, *self.args)) + f" ({self.source})"


def osc_cue(msg: OscMessage) -> Cue | Rejected:
    """The cue an OSC message asks for (``/handrig/<action> ARGS``), or why it is none."""
    if not msg.address.startswith(OSC_PREFIX):
        return "unknown"
    action = msg.address[len(OSC_PREFIX):]
    if action not in CUE_ACTIONS:
        return "unknown"
    low, high, _ = CUE_ACTIONS[action]
    args = msg.args
    if high == 0 and len(args) == 1 and isinstance(args[0], int | float):
        return "released" if args[0] == 0 else Cue(action)
    if not low <= len(args) <= high:
        return "malformed"
    words: list[str] = []
    for a in args:
        if not isinstance(a, str) or not a.strip() or len(a.split()) != 1:
            return "malformed"
        words.append(a)
    return Cue(action, tuple(words))


class CueLog:
    """The counts (:data:`COUNTS`, by source too) and the cues' events: every one kept up
    to ``events_kept`` (the total counted beyond), the last ``recent_kept`` for the panel.
    Written by the receivers' threads, read by any."""

    def __init__(self, clock: Clock, t0_s: float | None = None, *, events_kept: int = 200,
                 recent_kept: int = 8) -> None:
        self.clock = clock
        self.t0_s = clock.now() if t0_s is None else t0_s
        self.counts = dict.fromkeys(COUNTS, 0)
        self.by_source: dict[str, int] = {}
        self.events_total = 0
        self._events: deque[str] = deque(maxlen=events_kept)
        self._recent: deque[str] = deque(maxlen=recent_kept)
        self._lock = threading.Lock()

    def count(self, what: str, source: str, n: int = 1) -> None:
        with self._lock:
            self.counts[what] += n
            if what == "received":
                self.by_source[source] = self.by_source.get(source, 0) + n

    def event(self, text: str) -> str:
        """Keep ``text`` with the time since the run's start; returns the line kept."""
        line = f"{self.clock.now() - self.t0_s:7.2f} s  {text}"
        with self._lock:
            self.events_total += 1
            self._events.append(line)
            self._recent.append(text)
        return line

    def recent(self) -> tuple[str, ...]:
        """The last few cues (newest last), each naming its source."""
        with self._lock:
            return tuple(self._recent)

    def summary(self) -> dict[str, Any]:
        with self._lock:
            return {**self.counts, "by_source": dict(self.by_source),
                    "events": list(self._events), "events_total": self.events_total}


@dataclass(frozen=True)
class CueTargets:
    """What the cues act on. The controls are the session's (every hand at once, as the
    keys); each takes the reason that names the cue and its source. ``record_start``
    (a name or None) and ``record_stop`` return what they did, in words; ``play`` and
    ``layer`` are the layers' (``LayerControl.play``, ``LayerControl.layer``), None in a
    run without them. Any may raise a HandrigError: the cue is refused, the run goes on."""

    relax: Callable[[str], None]
    resume: Callable[[str], None]
    stop: Callable[[str], None]
    estop: Callable[[str], None]
    record_start: Callable[[str | None], str]
    record_stop: Callable[[], str]
    play: Callable[[str], None] | None = None
    layer: Callable[[str, str], None] | None = None


IGNORED_SAID = 5
"""Messages that are no cue said in the run's log, of each kind and source; the rest are
counted only (a controller sending faders to a wrong address must not flood the log)."""


class CueDispatcher:
    """Acts on cues, one at a time (OSC and MIDI arrive on threads of their own), and
    logs each in ``log``. ``on_event``: told every event line (the session's log), and
    the first :data:`IGNORED_SAID` messages of each kind that were no cue."""

    def __init__(self, targets: CueTargets, log: CueLog,
                 on_event: Callable[[str], None] = lambda text: None) -> None:
        self.targets = targets
        self.log = log
        self.on_event = on_event
        self._lock = threading.Lock()
        self._said: dict[tuple[str, str], int] = {}

    def reject(self, why: Rejected, source: str, what: str) -> None:
        """A message that is no cue: counted, and ignored."""
        self.log.count(why, source)
        if why == "released":
            return
        said = self._said[why, source] = self._said.get((why, source), 0) + 1
        if said <= IGNORED_SAID:
            self.on_event(f"cue ignored ({source}): {why}: {what}" + (
                f" (further {why} {source} messages are counted only)"
                if said == IGNORED_SAID else ""))

    def dispatch(self, cue: Cue) -> None:
        label = cue.label()
        with self._lock:
            try:
                done = self._act(cue, label)
            except HandrigError as exc:
                self.log.count("refused", cue.source)
                self.on_event(self.log.event(f"{label} refused: {exc}"))
                return
            self.log.count("acted", cue.source)
            self.on_event(self.log.event(done))

    def _act(self, cue: Cue, label: str) -> str:
        t, args = self.targets, cue.args
        match cue.action:
            case "relax":
                t.relax(label)
            case "resume":
                t.resume(label)
            case "stop":
                t.stop(label)
            case "estop":
                t.estop(label)
            case "record/start":
                return f"{label}: {t.record_start(args[0] if args else None)}"
            case "record/stop":
                return f"{label}: {t.record_stop()}"
            case "play" | "layer":
                return self._layers(cue, label)
            case _:
                raise HandrigError(f"no such cue: {cue.action}")
        return label

    def _layers(self, cue: Cue, label: str) -> str:
        t, args = self.targets, cue.args
        if cue.action == "play":
            if t.play is None:
                raise HandrigError("this run plays no takes onto the puppet (no layering)")
            t.play(args[0])
        else:
            if t.layer is None:
                raise HandrigError("this run layers no takes (no layering)")
            t.layer(args[0], args[1])
        return label
