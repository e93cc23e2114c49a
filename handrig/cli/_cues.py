"""The cue flags of ``run``, ``demo`` and ``play``: ``--osc-in``, ``--midi-in``,
``--cue-takes`` (docs/show.md, "Cues")."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from handrig.config.cues import CUE_ACTIONS, OSC_PREFIX, parse_listen_address

if TYPE_CHECKING:
    from handrig.app.cues.live import CueOptions
    from handrig.config.show import ShowFile


def add_cue_flags(parser: argparse.ArgumentParser) -> None:
    addresses = ", ".join(OSC_PREFIX + a for a in CUE_ACTIONS)
    parser.add_argument(
        "--osc-in", default=None, metavar="[HOST:]PORT",
        help=f"take cues over OSC (UDP) on PORT, on 127.0.0.1 unless a HOST is given (e.g. "
        f"0.0.0.0:9000): {addresses}; each acts as the key or button does")
    parser.add_argument(
        "--midi-in", default=None, metavar="NAME",
        help="take cues from the MIDI input NAME (virtual:NAME: a port of its own), notes "
        "and controllers mapped by the show file's [midi] table (needs handrig[show])")
    parser.add_argument(
        "--cue-takes", default=None, metavar="DIR",
        help="the folder of the takes /handrig/record/start begins (default: the show "
        "file's [cues] takes, else the current folder)")


def cue_options(args: argparse.Namespace, show: ShowFile | None = None) -> CueOptions | None:
    """The run's cues from the flags, the show file's tables filling what is not given
    (None when neither asks for an input). ConfigError for an address that is none."""
    from handrig.app.cues.live import CueOptions
    from handrig.config.cues import ShowMidi

    osc_in = args.osc_in or (show.osc.in_ if show is not None else "")
    midi_in = args.midi_in or (show.midi.port if show is not None else "")
    if not (osc_in or midi_in):
        return None
    if osc_in:
        parse_listen_address(osc_in, key="--osc-in" if args.osc_in else "osc.in")
    takes = args.cue_takes or (show.cues.takes if show is not None else "")
    return CueOptions(osc_in=osc_in, midi_in=midi_in,
                      midi=show.midi if show is not None else ShowMidi(), takes=takes)
