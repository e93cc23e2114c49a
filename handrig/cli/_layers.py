"""``--layer TAKE:GROUP`` on ``run``, ``demo`` and ``play``: takes layered under the glove."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from handrig.app.layering import LayerOptions
    from handrig.config.show import ShowFile


def add_layer_flag(p: Any) -> None:
    p.add_argument("--layer", action="append", default=None, metavar="TAKE:GROUP",
                   help="play a take (a performance .csv/.bvh from --record, or a name from "
                   "the show file's [takes]) onto GROUP while the glove drives the rest, "
                   "in step with the run, fading in over 0.5 s: GROUP a hand (right, left, "
                   "all), a finger (thumb, index, middle, ring, little; left.index on a "
                   "two-hand puppet), the wrist, or a comma list of curves (riIndexMCPy,...); "
                   "TAKE:GROUP:once plays it once and fades out with its end (default: "
                   "looped); repeatable; given, it replaces the show file's [[layer]]s")


def layer_options(args: argparse.Namespace, show: ShowFile | None = None) -> LayerOptions:
    """The session's layering from ``--layer`` (else the show file's ``[[layer]]``s) and
    the show file's ``[takes]``; ConfigError naming the flag or the show file's key."""
    from handrig.app.layering import LayerOptions, LayerSpec, parse_layer_flag

    if args.layer:
        specs = tuple(parse_layer_flag(text) for text in args.layer)
    elif show is not None:
        specs = tuple(LayerSpec(layer.take, layer.group, loop=layer.loop,
                                fade_s=layer.fade_s, key=f"layer[{i}]", file=show.path)
                      for i, layer in enumerate(show.layer))
    else:
        specs = ()
    return LayerOptions(takes=dict(show.takes) if show is not None else {}, layers=specs)
