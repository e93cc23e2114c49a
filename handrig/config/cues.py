"""The show's cue vocabulary and the show file's ``[osc]``, ``[midi]`` and ``[cues]`` tables.

A cue is one of :data:`CUE_ACTIONS` with its arguments, from a show controller: an OSC
message (``/handrig/<action> ARGS``) or a MIDI note or controller mapped to it in the
show file's ``[midi]`` table (``note.60 = "relax"``, ``cc.21 = "play intro"``). Each
acts as the show's key or button does (space, ``q``, ``e``; the view's buttons). The
vocabulary lives here, below the app, so that a show file's table is checked on load
against the same list the cue receiver dispatches on.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from handrig.errors import ConfigError

OSC_PREFIX = "/handrig/"
"""Every cue's OSC address starts with this: ``/handrig/relax``."""
DEFAULT_OSC_HOST = "127.0.0.1"

CUE_ACTIONS: dict[str, tuple[int, int, str]] = {
    "relax": (0, 0, "relax the puppet and hold it relaxed (as space)"),
    "resume": (0, 0, "follow the glove again, easing back in (as space again)"),
    "stop": (0, 0, "ease to relaxed, then torque off and end the run (as q)"),
    "estop": (0, 0, "torque off at once and end the run (as e)"),
    "record/start": (0, 1, "start a new take [NAME] (never over an existing one)"),
    "record/stop": (0, 0, "close the take that record/start opened"),
    "play": (1, 1, "play the take NAME from the show's [takes] onto the puppet, once"),
    "layer": (2, 2, "layer the take NAME onto GROUP (GROUP off: fade it out)"),
}
"""action -> (fewest arguments, most arguments, what it does). Arguments are strings."""

MIDI_CHANNELS = range(0, 17)
"""``[midi] channel``: 0 for every channel, else 1..16 (as a MIDI surface numbers them)."""


def cue_words(text: str, *, key: str = "", file: str | None = None
              ) -> tuple[str, tuple[str, ...]]:
    """``"layer intro left"`` -> ("layer", ("intro", "left")): an action of
    :data:`CUE_ACTIONS` and its arguments, counted; ConfigError naming ``key`` otherwise."""
    words = text.split()
    allowed = ", ".join(f'"{a}"' for a in CUE_ACTIONS)
    if not words or words[0] not in CUE_ACTIONS:
        raise ConfigError("not a cue", file=file, key=key or None, value=text,
                          allowed=f"one of {allowed}, then its arguments "
                          '(e.g. "play intro", "layer intro le")')
    action, args = words[0], tuple(words[1:])
    low, high, _ = CUE_ACTIONS[action]
    if not low <= len(args) <= high:
        want = str(low) if low == high else f"{low} or {high}"
        raise ConfigError(f"{action} takes {want} argument(s), got {len(args)}", file=file,
                          key=key or None, value=text,
                          allowed=f'"{action}" with {want} argument(s), e.g. '
                          + {"play": '"play intro"', "layer": '"layer intro le"',
                             "record/start": '"record/start" or "record/start act1"'}
                          .get(action, f'"{action}"'))
    return action, args


def parse_listen_address(text: str, *, key: str = "--osc-in") -> tuple[str, int]:
    """``"PORT"`` or ``"HOST:PORT"`` (``"[IPv6]:PORT"``) -> (host, port), on
    :data:`DEFAULT_OSC_HOST` unless a host is given; ConfigError naming ``key``."""
    host, sep, port_text = text.strip().rpartition(":")
    if not sep:
        host, port_text = DEFAULT_OSC_HOST, text.strip()
    host = host.strip("[]") or DEFAULT_OSC_HOST
    try:
        port = int(port_text)
    except ValueError:
        port = -1
    if not 0 <= port < 65536:
        raise ConfigError("not an address to listen on", key=key, value=text,
                          allowed="[HOST:]PORT with PORT 0..65535, e.g. 9000 (127.0.0.1 "
                          "only) or 0.0.0.0:9000 (every interface)")
    return host, port


@dataclass(frozen=True)
class ShowOsc:
    """``[osc]``: ``in = "[HOST:]PORT"``, the UDP port cues arrive on (as ``--osc-in``)."""

    in_: str = ""

    def check(self) -> None:
        if self.in_:
            parse_listen_address(self.in_, key="in")


@dataclass(frozen=True)
class ShowMidi:
    """``[midi]``: the MIDI input (``port``, as ``--midi-in``), the channel listened to
    (0: all), and which note (``note.N``, a note-on) or controller (``cc.N``, a value
    crossing 64 upwards) is which cue."""

    port: str = ""
    channel: int = 0
    note: dict[str, str] = field(default_factory=dict)
    cc: dict[str, str] = field(default_factory=dict)

    def check(self) -> None:
        if self.channel not in MIDI_CHANNELS:
            raise ConfigError("not a MIDI channel", key="channel", value=self.channel,
                              allowed="0 (every channel) or 1..16")
        for kind, table in (("note", self.note), ("cc", self.cc)):
            for number, text in table.items():
                if not number.isdigit() or not 0 <= int(number) <= 127:
                    raise ConfigError(f"not a MIDI {kind} number", key=f"{kind}.{number}",
                                      value=number, allowed="0..127, e.g. note.60")
                cue_words(text, key=f"{kind}.{number}")

    def cues(self) -> dict[tuple[str, int], tuple[str, tuple[str, ...]]]:
        """(``"note"`` or ``"cc"``, number) -> (action, arguments)."""
        return {(kind, int(number)): cue_words(text)
                for kind, table in (("note", self.note), ("cc", self.cc))
                for number, text in table.items()}


@dataclass(frozen=True)
class ShowCues:
    """``[cues]``: ``takes``, the folder a take started by ``record/start`` goes to
    (relative to the show file; empty: the current folder)."""

    takes: str = ""
