"""``handrig evaluate``: reconstruction error of a map, and of every method on unseen segments."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from handrig import hand, mocap
from handrig.commands import _mapio
from handrig.commands._numbers import positive_int
from handrig.evaluation import Errors, contiguous_folds, cross_validate, predict, rms_errors
from handrig.expand import DEFAULT_MAP
from handrig.maps import LinearMap

COMPARED = ("ridge", "huber", "paper", "mean")


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "evaluate", help="RMS error of a map against a BVH's own curves; methods side by side",
        description="1) the map's RMS reconstruction error per curve, per hand and overall"
        " (degrees) against the file's own curves; 2) each method (ridge, huber, the paper's"
        " single-controller map, the constant mean) with the map's controls, fitted without"
        " and tested on each held-out segment (the reference file's gesture clips, else"
        " --folds contiguous blocks): error on unseen motion.",
    )
    p.add_argument("file", metavar="FILE.bvh")
    p.add_argument("--map", default=str(DEFAULT_MAP), help="map TOML (default: shipped map)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--folds", type=positive_int, default=5,
                   help="held-out blocks for files without known clips (default 5)")
    p.add_argument("--no-compare", action="store_true", help="skip the held-out comparison")
    _mapio.add_input_args(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    lm = LinearMap.load(args.map)
    m = _mapio.load(args.file, args)
    m.require_clean("evaluation")
    own = rms_errors(predict(lm, m.curves), m.curves)
    lim = hand.curve_limits_deg()
    outside = ((m.curves < lim[:, 0]) | (m.curves > lim[:, 1])).mean(axis=0)
    in_sample = any(Path(t).name == Path(args.file).name for t in lm.trained_on)
    result: dict[str, Any] = {
        "file": args.file, "map": args.map, "method": lm.method, "controls": list(lm.controls),
        "frames": m.n_frames, "in_sample": in_sample, "map_errors": own.to_json(),
        "truth_outside_limits": {n: round(float(f), 4) for n, f in zip(
            m.names, outside, strict=True) if f > 0},
    }
    cv: dict[str, Errors] = {}
    if not args.no_compare:
        if _mapio.is_reference(args.file, m.n_frames) and args.fps is None:
            folds = [(a, b + 1) for _, a, b in mocap.REFERENCE_CLIPS]
            how = f"leave-one-clip-out over the {len(folds)} gesture clips of the README"
        else:
            folds = contiguous_folds(m.n_frames, args.folds)
            how = f"leave-one-block-out over {len(folds)} contiguous blocks"
        cv = cross_validate(m.curves, lm.controls, folds, COMPARED)
        result["held_out"] = {"scheme": how, "methods": {k: v.to_json() for k, v in cv.items()}}
    if args.json:
        print(json.dumps(result))
        return 0
    note = " (the map was trained on this file: in-sample)" if in_sample else ""
    print(f"map {args.map} ({lm.method}, controls {', '.join(lm.controls)}) on {args.file},"
          f" {m.n_frames} frames{note}")
    print(f"  RMS error: right hand {own.ri:.2f} deg, left hand {own.le:.2f} deg,"
          f" overall {own.overall:.2f} deg")
    worst = sorted(zip(own.per_curve, m.names, strict=True), reverse=True)[:5]
    print("  worst curves: " + ", ".join(f"{n} {v:.1f}" for v, n in worst))
    far = sorted(zip(outside, m.names, strict=True), reverse=True)[:3]
    if far[0][0] > 0:
        print("  the file itself leaves the joint limits (outputs are clamped, so this counts"
              " as error): " + ", ".join(f"{n} {f:.0%} of frames" for f, n in far if f > 0))
    if cv:
        print(f"unseen motion, {result['held_out']['scheme']}:")
        print(f"  {'method':<8} {'right (deg)':>12} {'left (deg)':>11} {'overall':>8}")
        for k, v in cv.items():
            label = {"ridge": "least squares on all controls, ridge penalty",
                     "huber": "robust (Huber) multi-control fit",
                     "paper": "the paper's single-controller map (4.2)",
                     "mean": "constant mean"}[k]
            print(f"  {k:<8} {v.ri:>12.2f} {v.le:>11.2f} {v.overall:>8.2f}   {label}")
    return 0
