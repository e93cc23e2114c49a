"""``handrig fit-map``: fit a linear map from a glove's control curves to all 50 curves."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
from numpy.typing import NDArray

from handrig.cli import _mapio
from handrig.cli._numbers import nonnegative_float
from handrig.errors import DataError
from handrig.offline import evaluation as evaluation_mod
from handrig.offline import fitting, mocap, validation
from handrig.pose import maps


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
    p.add_argument("--method", choices=fitting.METHODS, default=fitting.DEFAULT_METHOD,
                   help=f"fitting method (default {fitting.DEFAULT_METHOD}: the one chosen by"
                   " handrig evaluate's blocked validation)")
    p.add_argument("--alpha", type=nonnegative_float, default=fitting.RIDGE_ALPHA,
                   help=f"ridge penalty for ridge/huber (default {fitting.RIDGE_ALPHA:g})")
    p.add_argument("--noise", type=nonnegative_float, default=None,
                   help="robust and piecewise: how far (deg) live controls may sit from the"
                   f" training data (default {fitting.CONTROL_NOISE_DEG:g} for robust,"
                   f" {fitting.PIECEWISE_NOISE_DEG:g} for piecewise)")
    p.add_argument("--evaluate", action="store_true",
                   help="also measure the held-out errors (handrig evaluate's splits and its"
                   " blocked validation) of this method, mean, paper, ridge and robust on the"
                   " training data and record them in the map")
    p.add_argument("--description", default="", help="free text stored in the map")
    _mapio.add_input_args(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    controls = _mapio.parse_controls(args.controls)
    parts = []
    labels: list[NDArray[np.intp]] = []
    fps = None
    reference = False
    conditioned: list[str] = []
    for f in args.files:
        m = _mapio.load(f, args)
        m.require_clean("fitting a map")
        reference = len(args.files) == 1 and _mapio.is_reference(f, m.n_frames) and (
            args.fps is None)
        base = int(sum(int(lb.max()) + 1 for lb in labels))
        labels.append(base + (mocap.reference_clip_labels() if reference
                              else fitting.block_groups(m.n_frames)))
        parts.append(m.curves)
        if m.offsets_deg is not None:
            conditioned.append(f"{f}: {int((m.offsets_deg != 0).sum())} curves")
        fps = m.fps if fps is None else fps
    curves = np.concatenate(parts)
    groups = np.concatenate(labels)
    evaluation: list[str] = []
    if args.evaluate:
        if reference:
            splits, _ = evaluation_mod.reference_splits(curves, fps or 0.0)
        else:
            splits = evaluation_mod.block_splits(curves, fps or 0.0, fitting.DEFAULT_GROUPS)[0]
            if len(args.files) > 1:
                print("note: held-out figures over contiguous blocks of the concatenated files")
        methods = tuple(dict.fromkeys((args.method, "mean", "paper", "ridge", "robust")))
        res = evaluation_mod.out_of_regime(curves, controls, splits, groups, methods)
        for sp in splits:
            cells = "; ".join(f"{k} {v.ri:.2f} right, {v.le:.2f} left"
                              for k, v in res[sp.name].items())
            evaluation.append(f"{sp.name} ({sp.description}): {cells}")
        calm = evaluation_mod.calm_frames(curves, fps or 0.0, groups)
        blocked = validation.blocked_splits(len(curves), fps or 0.0, calm)
        res = evaluation_mod.out_of_regime(curves, controls, blocked, groups, methods)
        for sp in blocked:
            cells = "; ".join(f"{k} {v.ri:.2f} (sd {validation.spread(v.ri_folds)[0]:.2f})"
                              f" right, {v.le:.2f} left" for k, v in res[sp.name].items())
            evaluation.append(f"{sp.name} ({sp.description}): {cells}")
    lm = fitting.fit_map(
        curves, controls, args.method, alpha=args.alpha,
        control_noise_deg=fitting.CONTROL_NOISE_DEG if args.noise is None else args.noise,
        piecewise_noise_deg=(fitting.PIECEWISE_NOISE_DEG if args.noise is None
                             else args.noise),
        groups=groups, groups_name=(
            "the gesture clips of the README" if reference
            else f"{fitting.DEFAULT_GROUPS} contiguous blocks per file"),
        trained_on=tuple(args.files), profile=str(args.profile),
        fps=fps or 0.0, description=args.description, evaluation=tuple(evaluation),
        conditioning=(f"trained on conditioned curves (calibration offsets of profile"
                      f" {args.profile}: {'; '.join(conditioned)})" if conditioned else ""),
    )
    path = lm.save(args.out)
    if lm.fit_rms_deg is None:
        raise DataError("internal: a fitted map has no in-sample error")
    fit = lm.fit_rms_deg
    print(f"{args.method} map, {len(controls)} controls, {curves.shape[0]} frames from"
          f" {len(args.files)} file(s) -> {path}")
    if lm.fitting:
        print(f"  {lm.fitting}")
    print(f"in-sample RMS error: right hand {np.sqrt(np.mean(fit[:25] ** 2)):.2f} deg, left"
          f" {np.sqrt(np.mean(fit[25:] ** 2)):.2f} deg (held-out figures: handrig evaluate)")
    for line in evaluation:
        print(f"  held out, {line}")
    return 0
