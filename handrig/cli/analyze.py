"""``handrig analyze``: the dimensionality analysis of Jörg & O'Sullivan on a BVH file."""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

import numpy as np

from handrig.cli._numbers import nonnegative_float, positive_float
from handrig.offline import conditioning, mocap
from handrig.offline.analysis import Thresholds, analyze
from handrig.offline.report import tables_markdown, write_report


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "analyze",
        help="ranges, rmsd1/rmsd2 and the four simplification steps (Tables 1-5) of a BVH",
        description="Sections 4-5 of Jörg & O'Sullivan on the 50 curves of a BVH file, as the"
        " profile maps them (channel angles in degrees, signs unchanged).",
    )
    p.add_argument("file", help="BVH motion capture file")
    p.add_argument("--profile", default="perception_neuron",
                   help="joint-mapping profile name or .toml path (default perception_neuron)")
    p.add_argument("--out", default=None, help="write report.md and PNG figures here")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--fps", type=positive_float, default=None,
                   help="resample to this rate first (the paper used 30); default: file's rate")
    p.add_argument("--despike", action="store_true",
                   help="repair NaN/absurd values and single-frame spikes before analysing")
    for name, default, what in (
        ("range-small", 1.0, "step 1 range threshold, deg"),
        ("rmsd-strict", 0.3, "step 2 rmsd threshold"),
        ("range-large", 5.0, "step 3 range threshold, deg"),
        ("rmsd-loose", 0.5, "step 4 rmsd threshold"),
    ):
        p.add_argument(f"--{name}", type=nonnegative_float, default=default,
                       help=f"{what} ({default:g})")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    m = mocap.load_curves(args.file, args.profile, "raw", fps=args.fps, despike=args.despike)
    notes = []
    if m.glitches:
        state = "repaired (--despike)" if m.repaired else "NOT repaired: pass --despike"
        notes.append(f"{len(m.glitches)} glitch(es) found, {state}: "
                     + "; ".join(str(g) for g in m.glitches[:10]))
        print(f"handrig: warning: {notes[-1]}", file=sys.stderr)
    th = Thresholds(args.range_small, args.rmsd_strict, args.range_large, args.rmsd_loose)
    an = analyze(m.curves, th)
    cond = _conditioning(args, m, th)
    notes.append(cond["text"])
    if args.out:
        path = write_report(an, m.curves, args.out, title=str(args.file), fps=m.fps, notes=notes)
        if not args.json:
            print(f"report written to {path}")
    if args.json:
        obj = an.to_json()
        obj["fps"] = m.fps
        obj["profile"] = m.profile
        obj["conditioning"] = {k: v for k, v in cond.items() if k != "text"}
        obj["glitches"] = [
            {"curve": g.curve, "frame": g.frame, "kind": g.kind, "repaired": m.repaired,
             "value": g.value if math.isfinite(g.value) else str(g.value)}
            for g in m.glitches
        ]
        print(json.dumps(obj, allow_nan=False))
        return 0
    if not args.out:
        print(tables_markdown(an))
        print(f"\n{cond['text']}")
    return 0


def _conditioning(args: argparse.Namespace, m: mocap.MocapCurves, th: Thresholds
                  ) -> dict[str, Any]:
    """The profile's calibration offsets, the offsets this file suggests, and the check
    that the analysis is the same on the conditioned curves (it works on raw curves:
    an offset of ``o`` deg in the vocabulary is ``sign * o`` on the raw channel)."""
    prof = mocap.load_profile(args.profile)
    sign, _ = mocap.profile_affine(prof)
    applied = prof.calibration.vector()
    voc = mocap.to_vocabulary(m.curves, prof)
    finite = bool(np.isfinite(voc).all())
    suggested = conditioning.find_offsets(voc) if finite else np.zeros(len(m.names))
    same, moved = conditioning.analysis_unchanged(m.curves, sign * applied, th)
    same_s, moved_s = conditioning.analysis_unchanged(m.curves, sign * suggested, th)

    def named(v: np.ndarray) -> dict[str, float]:
        return {n: round(float(x), 2) for n, x in zip(m.names, v, strict=True) if x}

    ok = same and same_s
    shown = ", ".join(f"{n} {v:+.1f}" for n, v in named(suggested).items()) or "none"
    text = (f"calibration offsets (vocabulary deg): profile {prof.name} adds"
            f" {len(named(applied))} ({prof.calibration.how or 'none recorded'}); offsets"
            f" this file suggests: {shown}"
            + ("" if finite else " (not computed: NaN/inf in the curves, pass --despike)")
            + f". The analysis of the conditioned curves is {'the same' if ok else 'NOT the same'}"
            f" (every stage's constant curves, links and DOFs; ranges and rmsds move by at"
            f" most {max(moved, moved_s):.1g})")
    return {"profile_offsets_deg": named(applied), "suggested_offsets_deg": named(suggested),
            "analysis_unchanged": ok, "max_change": max(moved, moved_s), "text": text}
