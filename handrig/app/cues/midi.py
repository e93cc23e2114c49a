"""MIDI cues: a note or a controller mapped to a cue by the show file's ``[midi]`` table
(:class:`MidiCues`), from a MIDI input opened with mido on python-rtmidi
(:class:`MidiReceiver`; the optional extra ``handrig[show]``).

A note-on (velocity above 0) acts; a controller acts when its value rises to 64 or more
from below (a surface's button sends 127 pressed, 0 released; a fader acts once as it
passes the middle). Note-offs, releases and the system's real-time messages (clock,
active sensing) are no cues and are not counted; a note, controller or other channel
message the table does not map is counted as unmapped. ``[midi] channel`` 1..16 listens
to that channel only (0: every channel).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Literal

from handrig.app.cues.dispatch import Cue, CueDispatcher
from handrig.config.cues import ShowMidi
from handrig.errors import ConfigError, DeviceError

if TYPE_CHECKING:
    import mido

VIRTUAL_PREFIX = "virtual:"
"""``--midi-in virtual:NAME``: a port of handrig's own that other programs send to."""
_CHANNEL_TYPES = ("note_on", "note_off", "control_change", "program_change", "pitchwheel",
                  "aftertouch", "polytouch")


class MidiCues:
    """MIDI messages (mido's) to cues, as ``table`` maps them."""

    def __init__(self, table: ShowMidi) -> None:
        self.cues = table.cues()
        self.channel = table.channel - 1  # mido counts channels from 0; -1: all
        self._cc_high: set[tuple[int, int]] = set()  # (channel, cc) held at 64 or more

    def cue(self, msg: mido.Message) -> Cue | Literal["unmapped"] | None:
        """The cue ``msg`` asks for, "unmapped", or None (no cue: ignored, not counted)."""
        kind = msg.type
        if kind not in _CHANNEL_TYPES:
            return None  # clock, active sensing, sysex ...
        if self.channel >= 0 and msg.channel != self.channel:
            return None
        if kind == "note_on" and msg.velocity > 0:
            key: tuple[str, int] = ("note", msg.note)
        elif kind == "control_change":
            held = (msg.channel, msg.control)
            if msg.value < 64:
                self._cc_high.discard(held)
                return None
            if held in self._cc_high:
                return None
            self._cc_high.add(held)
            key = ("cc", msg.control)
        elif kind in ("note_on", "note_off"):
            return None
        else:
            return "unmapped"
        found = self.cues.get(key)
        if found is None:
            return "unmapped"
        return Cue(found[0], found[1], "MIDI")

    def handle(self, msg: mido.Message, dispatcher: CueDispatcher) -> None:
        """Count ``msg`` and act on its cue (the receiver's callback)."""
        cue = self.cue(msg)
        if cue is None:
            return
        dispatcher.log.count("received", "MIDI")
        if isinstance(cue, str):
            dispatcher.reject("unmapped", "MIDI", str(msg))
        else:
            dispatcher.dispatch(cue)


def check_midi() -> None:
    """ConfigError naming ``--midi-in`` and the fix when mido or python-rtmidi is missing."""
    _mido()


def _mido() -> Any:
    try:
        import mido
        import rtmidi  # noqa: F401  (mido's default backend)
    except ImportError:
        raise ConfigError("MIDI input needs mido and python-rtmidi", key="--midi-in",
                          allowed="pip install 'handrig[show]'") from None
    return mido


class MidiReceiver:
    """The MIDI input ``name`` (``virtual:NAME``: a virtual port of its own), each message
    handed to ``cues`` on rtmidi's thread, from construction to :meth:`close`."""

    def __init__(self, name: str, cues: MidiCues, dispatcher: CueDispatcher, *,
                 flag: str = "--midi-in") -> None:
        mido = _mido()
        self.cues, self.dispatcher = cues, dispatcher
        virtual = name.startswith(VIRTUAL_PREFIX)
        port_name = name.removeprefix(VIRTUAL_PREFIX)
        try:
            self._port = mido.open_input(port_name, virtual=virtual, callback=self._on_message)
        except (OSError, SystemError, RuntimeError, ValueError) as exc:
            raise DeviceError(
                f"{flag} {name!r}: cannot open the MIDI input ({exc}); "
                + ("the inputs here: " + (", ".join(_input_names(mido)) or "none")
                   if not virtual else "this machine has no MIDI sequencer (ALSA: "
                   "/dev/snd/seq, the snd-seq module)")) from None
        self.name = name

    def _on_message(self, msg: mido.Message) -> None:
        self.cues.handle(msg, self.dispatcher)

    def close(self) -> None:
        self._port.close()


def _input_names(mido: Any) -> list[str]:
    try:
        return list(mido.get_input_names())
    except (OSError, SystemError, RuntimeError):
        return []
