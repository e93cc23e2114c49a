"""``handrig expand``: a map + a BVH's control curves -> every frame's 50-curve pose (CSV)."""

from __future__ import annotations

import argparse
import csv
import sys
from typing import Any

import numpy as np

from handrig import hand
from handrig.cli import _mapio
from handrig.errors import DataError
from handrig.pose.expand import DEFAULT_MAP, Expander


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "expand", help="expand a BVH's control curves into all 50 curves through a map (CSV)",
        description="Reads the map's control curves from the BVH and writes one row per frame:"
        " the 50 curves in degrees (vocabulary convention, clamped to the joint limits),"
        " header row = curve names.",
    )
    p.add_argument("file", metavar="FILE.bvh")
    p.add_argument("--map", default=str(DEFAULT_MAP), help="map TOML (default: shipped map)")
    p.add_argument("--out", required=True, help="CSV file to write ('-' for stdout)")
    _mapio.add_input_args(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    ex = Expander.from_file(args.map)
    m = _mapio.load(args.file, args)
    bad = [g for g in m.glitches if g.curve in ex.controls]
    if bad and not m.repaired:
        raise DataError(
            f"{args.file}: {len(bad)} glitch(es) in the control curves, first {bad[0]};"
            " pass --despike to repair them"
        )
    idx = np.array([hand.curve_index(c) for c in ex.controls], dtype=np.intp)
    pose = ex.expand_many(np.ascontiguousarray(m.curves[:, idx]))
    try:
        fh = sys.stdout if args.out == "-" else open(args.out, "w", newline="")  # noqa: SIM115
    except OSError as exc:
        raise DataError(f"cannot write {args.out}: {exc}") from None
    try:
        w = csv.writer(fh)
        w.writerow(hand.CURVE_NAMES)
        w.writerows([f"{v:.4f}" for v in row] for row in pose)
    finally:
        if fh is not sys.stdout:
            fh.close()
    summary = ex.training_range().summary()
    if args.out != "-":
        print(f"{pose.shape[0]} frames x {pose.shape[1]} curves -> {args.out}")
        print(summary)
    else:
        print(summary, file=sys.stderr)
    return 0
