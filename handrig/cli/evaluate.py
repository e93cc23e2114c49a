"""``handrig evaluate``: reconstruction error of a map, and of every method on unseen segments."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from handrig import hand
from handrig.cli import _mapio
from handrig.cli._numbers import nonnegative_float, positive_int
from handrig.errors import DataError
from handrig.offline.evaluation import (
    REGIME_METHODS,
    Errors,
    Split,
    block_splits,
    calm_frames,
    clamped_fractions,
    group_rms,
    out_of_regime,
    predict,
    reference_splits,
    regime_table,
    rms_errors,
    write_error_figure,
)
from handrig.offline.fitting import CONTROL_NOISE_DEG, METHODS, PIECEWISE_NOISE_DEG
from handrig.offline.validation import (
    GAP_S,
    best_methods,
    blocked_splits,
    validation_json,
    validation_table,
)
from handrig.pose.expand import DEFAULT_MAP
from handrig.pose.maps import LinearMap

LABELS = {"ridge": "least squares on all controls, ridge penalty",
          "huber": "robust (Huber) multi-control fit",
          "paper": "the paper's single-controller map (4.2)",
          "mean": "constant mean",
          "robust": f"shrunk toward the paper map for controls off by {CONTROL_NOISE_DEG:g} deg,"
                    " per-curve CV vs mean",
          "piecewise": "piecewise-linear (each control's slope may change at its training"
                       f" median), shrunk toward the mean pose for controls off by"
                       f" {PIECEWISE_NOISE_DEG:g} deg"}


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "evaluate", help="RMS error of a map against a BVH's own curves; methods side by side",
        description="1) the map's RMS reconstruction error per curve, per hand and overall"
        " (degrees) against the file's own curves; 2) each method (the constant mean, the"
        " paper's single-controller map, ridge, robust, piecewise) with the map's controls,"
        " fitted"
        " without and tested on held-out data, split by split: leave one clip out (the"
        " reference file's gesture clips, else --folds contiguous blocks), train on some"
        " kinds of gesture and test on another, the calm frames of each held-out clip"
        " (fit with and without calm frames), and held-out clips with every control off"
        " by 2 deg; 3) the validation that predicts unseen takes: --folds blocks of time"
        " held out with --gap-s seconds on each side that neither train nor test (all"
        " frames, the calm ones, controls off by 2 deg) and the other hand (fit on one hand,"
        " tested mirrored on the other), each figure with its spread across the blocks.",
    )
    p.add_argument("file", metavar="FILE.bvh")
    p.add_argument("--map", default=str(DEFAULT_MAP), help="map TOML (default: shipped map)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--folds", type=positive_int, default=5,
                   help="held-out blocks of time for the blocked validation, and for the"
                   " leave-one-out splits of files without known clips (default 5)")
    p.add_argument("--gap-s", type=nonnegative_float, default=GAP_S,
                   help="seconds on each side of a held-out block that neither train nor"
                   f" test (default {GAP_S:g})")
    p.add_argument("--no-compare", action="store_true", help="skip the held-out comparison")
    p.add_argument("--methods", default=",".join(REGIME_METHODS),
                   help=f"methods compared (default {','.join(REGIME_METHODS)};"
                   f" any of {','.join(METHODS)})")
    p.add_argument("--figure", metavar="PNG", default=None,
                   help="write the held-out RMS error per curve, per split and method")
    _mapio.add_input_args(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    lm = LinearMap.load(args.map)
    m = _mapio.load(args.file, args)
    m.require_clean("evaluation")
    own = rms_errors(predict(lm, m.curves), m.curves)
    lim = hand.curve_limits_deg()
    outside = ((m.curves < lim[:, 0]) | (m.curves > lim[:, 1])).mean(axis=0)
    cond, cond_lines = _mapio.conditioning_report(args.file, m, args)
    ri_c, le_c = clamped_fractions(lm, m.curves)
    in_sample = any(Path(t).name == Path(args.file).name for t in lm.trained_on)
    result: dict[str, Any] = {
        "file": args.file, "map": args.map, "method": lm.method, "controls": list(lm.controls),
        "frames": m.n_frames, "in_sample": in_sample,
        "map_errors": {**own.to_json(), "ri_clamped_fraction": round(ri_c, 6),
                       "le_clamped_fraction": round(le_c, 6)},
        "conditioning": cond,
        "truth_outside_limits": {n: round(float(f), 4) for n, f in zip(
            m.names, outside, strict=True) if f > 0},
    }
    res: dict[str, dict[str, Errors]] = {}
    val: dict[str, dict[str, Errors]] = {}
    splits: list[Split] = []
    val_splits: list[Split] = []
    if not args.no_compare:
        methods = tuple(x.strip() for x in args.methods.split(",") if x.strip())
        bad = [x for x in methods if x not in METHODS]
        if bad or not methods:
            raise DataError(f"--methods: unknown {', '.join(bad) or '(none)'}; methods:"
                            f" {', '.join(METHODS)}")
        if _mapio.is_reference(args.file, m.n_frames) and args.fps is None:
            splits, groups = reference_splits(m.curves, m.fps)
            how = f"leave-one-clip-out over the {len(set(groups))} gesture clips of the README"
        else:
            splits, groups = block_splits(m.curves, m.fps, args.folds)
            how = f"leave-one-block-out over {args.folds} contiguous blocks"
        res = out_of_regime(m.curves, lm.controls, splits, groups, methods)
        calm = calm_frames(m.curves, m.fps, groups)
        val_splits = blocked_splits(m.n_frames, m.fps, calm, args.folds, args.gap_s)
        val = out_of_regime(m.curves, lm.controls, val_splits, groups, methods)
        result["validation"] = validation_json(val, val_splits)
        result["validation_best"] = best_methods(val)
        result["held_out"] = {"scheme": how, "methods": {
            k: v.to_json() for k, v in res["clips"].items()}}
        result["out_of_regime"] = {sp.name: {
            "description": sp.description,
            "methods": {k: {"ri_rms_deg": round(v.ri, 4), "le_rms_deg": round(v.le, 4),
                            **v.clamped_json(),
                            "ri_groups_rms_deg": {g: round(x, 4)
                                                  for g, x in group_rms(v).items()},
                            "le_groups_rms_deg": {g: round(x, 4)
                                                  for g, x in group_rms(v, "le").items()}}
                        for k, v in res[sp.name].items()}} for sp in splits}
        if args.figure:
            fig = write_error_figure(res, args.figure, title=f"held-out RMS error per curve,"
                                     f" controls {', '.join(lm.controls)}")
            result["figure"] = str(fig)
    if args.json:
        print(json.dumps(result))
        return 0
    note = " (the map was trained on this file: in-sample)" if in_sample else ""
    print(f"map {args.map} ({lm.method}, controls {', '.join(lm.controls)}) on {args.file},"
          f" {m.n_frames} frames{note}")
    print("\n".join(cond_lines))
    print(f"  RMS error: right hand {own.ri:.2f} deg, left hand {own.le:.2f} deg,"
          f" overall {own.overall:.2f} deg; the map's output outside the joint limits (then"
          f" clamped): right {ri_c:.2%}, left {le_c:.2%} of values")
    worst = sorted(zip(own.per_curve, m.names, strict=True), reverse=True)[:5]
    print("  worst curves: " + ", ".join(f"{n} {v:.1f}" for v, n in worst))
    far = sorted(zip(outside, m.names, strict=True), reverse=True)[:3]
    if far[0][0] > 0:
        print("  the file itself leaves the joint limits (outputs are clamped, so this counts"
              " as error): " + ", ".join(f"{n} {f:.1%} of frames" for f, n in far if f > 0))
    if res:
        print(f"unseen motion, {result['held_out']['scheme']} (RMS deg, every curve of the"
              " hand, and its curve groups):")
        for sp in splits:
            print(f"  {sp.name}: {sp.description}")
        print("\n".join(regime_table(res, splits)))
        print("  clamp% = the hand's predicted values the joint limits clamped")
        print("  methods: " + "; ".join(f"{k} = {LABELS[k]}" for k in res["clips"]))
        print(f"validation that predicts unseen takes: {args.folds} blocks of time held out,"
              f" {args.gap_s:g} s on each side in neither training nor test (RMS deg; the"
              " right hand's spread across the blocks: sd and worst block):")
        for sp in val_splits:
            print(f"  {sp.name}: {sp.description}")
        print("\n".join(validation_table(val, val_splits)))
        best = result["validation_best"]
        print("  lowest right-hand RMS: " + ", ".join(f"{k} {v}" for k, v in best.items()))
        if args.figure:
            print(f"figure: {result['figure']}")
    return 0
