"""A live session's cues: the OSC port and the MIDI input, acting on every hand as the
show's keys do, and the takes they and the ``r`` key start (:class:`LiveCues`, built by
:func:`open_cues`).

The session (:mod:`handrig.app.session`) calls :func:`open_cues` once its outputs are
built (the OSC port is bound then, so a port that is taken fails the run before torque
goes on; the takes join the first hand's outputs), calls :meth:`LiveCues.start` once the
loops are built, binds ``r`` to :meth:`LiveCues.record_key`, and puts
:meth:`LiveCues.summary` in the run's summary under ``cues`` when there was a cue input
or a cue (:attr:`LiveCues.used`).
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from handrig.app.cues.dispatch import Cue, CueDispatcher, CueLog, CueTargets
from handrig.app.cues.midi import MidiCues, MidiReceiver, check_midi
from handrig.app.cues.receiver import OscReceiver
from handrig.app.cues.takes import CueTakes
from handrig.app.hands import AllHands
from handrig.clock import Clock
from handrig.config.cues import OSC_PREFIX, ShowMidi, parse_listen_address
from handrig.config.rig import LoopConfig


@dataclass(frozen=True)
class CueOptions:
    """``osc_in``: ``[HOST:]PORT`` (``--osc-in``, ``[osc] in``); ``midi_in``: a MIDI input's
    name (``--midi-in``, ``[midi] port``; ``virtual:NAME`` a port of its own) and
    ``midi`` its table; ``takes``: the folder of the takes ``record/start`` begins (""
    the current one); ``play``, ``layer``: the layers' controls (``LayerControl.play``
    and ``.layer``), None when the run has none."""

    osc_in: str = ""
    midi_in: str = ""
    midi: ShowMidi = field(default_factory=ShowMidi)
    takes: str = ""
    play: Callable[[str], None] | None = None
    layer: Callable[[str, str], None] | None = None

    @property
    def wanted(self) -> bool:
        return bool(self.osc_in or self.midi_in)


class LiveCues:
    """The cue side of one run. ``hands``: the session's controls of every hand;
    ``rate_hz``: a BVH take's frame rate; ``log``: the run's event lines; ``priority``:
    the OSC thread's SCHED_FIFO priority (0: normal; see :class:`OscReceiver`)."""

    def __init__(self, opts: CueOptions, hands: AllHands, clock: Clock, rate_hz: float,
                 log: Callable[[str], None], *, priority: int = 0) -> None:
        self.opts = opts
        self._log = log
        self.log = CueLog(clock)
        self.takes = CueTakes(opts.takes, rate_hz, log=log)
        targets = CueTargets(relax=hands.relax, resume=hands.resume,
                             stop=hands.request_stop, estop=hands.estop,
                             record_start=self.takes.start, record_stop=self.takes.stop,
                             play=opts.play, layer=opts.layer)
        self.dispatcher = CueDispatcher(targets, self.log, on_event=log)
        hands.cue_source = self.log.recent  # the view shows them
        self.osc: OscReceiver | None = None
        self.midi: MidiReceiver | None = None
        self._midi_cues = MidiCues(opts.midi)
        if opts.midi_in:
            check_midi()  # mido and python-rtmidi there: said before torque goes on
        if opts.osc_in:
            host, port = parse_listen_address(opts.osc_in)
            self.osc = OscReceiver(host, port, self.dispatcher, priority=priority)
            self.osc.on_error = log

    def attach_layers(self, play: Callable[[str], None],
                      layer: Callable[[str, str], None]) -> None:
        """``/handrig/play`` and ``/handrig/layer`` call these from now on (the layers'
        ``LayerControl.play`` and ``.layer``, when they are built inside the session,
        after :func:`open_cues`; else pass them in :class:`CueOptions`). Before
        :meth:`start`."""
        self.dispatcher.targets = dataclasses.replace(self.dispatcher.targets, play=play,
                                                      layer=layer)

    def start(self) -> None:
        """Cues act from now on (the loops are built)."""
        self.log.t0_s = self.log.clock.now()
        if self.opts.midi_in and self.midi is None:
            self.midi = MidiReceiver(self.opts.midi_in, self._midi_cues, self.dispatcher)
        if self.osc is not None:
            self.osc.start()
            self._log(f"cues: OSC on {self.osc.host}:{self.osc.port} ({OSC_PREFIX}...)")
        if self.midi is not None:
            self._log(f"cues: MIDI from {self.midi.name}")

    def close(self) -> None:
        """The inputs closed, then the open take (as ``record/stop``)."""
        for receiver in (self.osc, self.midi):
            if receiver is not None:
                with contextlib.suppress(OSError):
                    receiver.close()
        self.takes.close()

    def record_key(self) -> None:
        """The ``r`` key: start a take (a generated name), or stop the one recording."""
        action = "record/stop" if self.takes.recording else "record/start"
        self.log.count("received", "key")
        self.dispatcher.dispatch(Cue(action, (), "key"))

    @property
    def used(self) -> bool:
        """Whether the run had a cue input or took a cue (its summary part is wanted)."""
        return self.opts.wanted or self.log.events_total > 0

    def recent(self) -> tuple[str, ...]:
        """The last few cues, each naming its source (the panel, the view)."""
        return self.log.recent()

    def summary(self) -> dict[str, Any]:
        """``cues``: the counts, by source, every cue's event, the takes, the inputs."""
        s = self.log.summary()
        s["takes"] = self.takes.summary()
        s["osc_in"] = f"{self.osc.host}:{self.osc.port}" if self.osc is not None else ""
        s["midi_in"] = self.opts.midi_in
        return s


def open_cues(stack: contextlib.ExitStack, opts: CueOptions | None, hands: AllHands,
              clock: Clock, outputs: list[Any], rate_hz: float, log: Callable[[str], None],
              loop: LoopConfig | None = None) -> LiveCues:
    """The run's cues (without an input asked for: the ``r`` key's takes only), closed
    when ``stack`` unwinds; their takes appended to ``outputs`` (the first hand's loop's:
    the full pose). ``loop``: the rig's loop settings (the OSC thread's priority is one
    below the loop's)."""
    priority = loop.realtime_priority - 1 if loop is not None else 0
    cues = LiveCues(opts or CueOptions(), hands, clock, rate_hz, log,
                    priority=max(priority, 0))
    stack.callback(cues.close)
    outputs.append(cues.takes)
    return cues
