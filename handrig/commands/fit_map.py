"""``handrig fit-map``: fit a linear map from a glove's control curves to all 50 curves."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from handrig import maps
from handrig.commands import _mapio
from handrig.commands._numbers import nonnegative_float


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "fit-map", help="fit a map from control curves (a glove's channels) to all 50 curves",
        description="Fit curve = mean + gains * (controls - means) on BVH captures, in the"
        " vocabulary convention; write a readable TOML map.",
    )
    p.add_argument("files", nargs="+", metavar="FILE.bvh", help="training captures")
    p.add_argument("--controls", default=",".join(maps.DEFAULT_RIGHT_CONTROLS),
                   help="comma-separated control curves (default: the paper's right-glove set"
                   f" {','.join(maps.DEFAULT_RIGHT_CONTROLS)})")
    p.add_argument("--out", required=True, help="map TOML file to write")
    p.add_argument("--method", choices=maps.METHODS, default=maps.DEFAULT_METHOD,
                   help=f"fitting method (default {maps.DEFAULT_METHOD}: best on unseen gestures)")
    p.add_argument("--alpha", type=nonnegative_float, default=maps.RIDGE_ALPHA,
                   help=f"ridge penalty for ridge/huber (default {maps.RIDGE_ALPHA:g})")
    p.add_argument("--description", default="", help="free text stored in the map")
    _mapio.add_input_args(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    controls = _mapio.parse_controls(args.controls)
    parts = []
    fps = None
    for f in args.files:
        m = _mapio.load(f, args)
        m.require_clean("fitting a map")
        parts.append(m.curves)
        fps = m.fps if fps is None else fps
    curves = np.concatenate(parts)
    lm = maps.fit_map(
        curves, controls, args.method, alpha=args.alpha, trained_on=tuple(args.files),
        profile=str(args.profile), fps=fps or 0.0, description=args.description,
    )
    path = lm.save(args.out)
    assert lm.fit_rms_deg is not None
    fit = lm.fit_rms_deg
    print(f"{args.method} map, {len(controls)} controls, {curves.shape[0]} frames from"
          f" {len(args.files)} file(s) -> {path}")
    print(f"in-sample RMS error: right hand {np.sqrt(np.mean(fit[:25] ** 2)):.2f} deg, left"
          f" {np.sqrt(np.mean(fit[25:] ** 2)):.2f} deg (held-out figures: handrig evaluate)")
    return 0
