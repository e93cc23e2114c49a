"""The one flag that names a rig, shared by every command that uses one.

``--rig NAME|FILE``: a preset (``config/rigs/NAME.toml``: ``leap``, ...) or a rig
file; without it, your ``rig.toml`` ($XDG_CONFIG_HOME/handrig) when there is one,
else the shipped ``config/rig.toml``. ``--config FILE`` is still accepted for the
rig (its older name in ``run`` and ``calibrate servos``) and means the same.
"""

from __future__ import annotations

import argparse
import sys
from typing import TextIO

from handrig.app.sources import Source, format_sources
from handrig.config.paths import CONFIG_HOME_HELP
from handrig.config.rig_files import presets

RIG_HELP = ("rig preset ({presets}) or rig file (default: rig.toml in "
            f"{CONFIG_HOME_HELP} when there is one, else the shipped config/rig.toml)")


def add_rig_argument(p: argparse.ArgumentParser, *, old_name: bool = True,
                     help_text: str | None = None) -> None:
    """Add ``--rig NAME|FILE`` (dest ``rig``); ``old_name`` also accepts ``--config``."""
    p.add_argument("--rig", default=None, metavar="NAME|FILE",
                   help=help_text or RIG_HELP.format(presets=", ".join(presets())))
    if old_name:
        p.add_argument("--config", dest="rig", default=None, help=argparse.SUPPRESS)


def print_sources(sources: list[Source], *, stream: TextIO | None = None) -> None:
    """Print the files in use (to stdout unless ``stream``) and flush."""
    print(format_sources(sources), file=stream or sys.stdout, flush=True)
