"""``handrig record repair FILE``: make a take cut short by a crash readable."""

from __future__ import annotations

import argparse
import json
from typing import Any

from handrig.outputs.recorder import repair


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "record",
        help="recordings made by `handrig run --record`: repair a take cut short",
        description="Tools for takes recorded by `handrig run --record`.",
    )
    actions = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    r: argparse.ArgumentParser = actions.add_parser(
        "repair",
        help="keep every whole frame of a take cut short (crash, kill, power cut)",
        description="A take is written to TAKE.partial while the show runs and renamed to"
        " TAKE when the run ends. After a crash, repair TAKE.partial (or TAKE): everything"
        " after the last whole frame is cut, a BVH header gets the frame count, and"
        " TAKE.partial becomes TAKE (unless TAKE exists). Safe to run on a whole file.",
    )
    r.add_argument("file", nargs="+", help="TAKE.partial, TAKE.csv or TAKE.bvh")
    r.add_argument("--json", action="store_true", help="print what was done as JSON")
    r.set_defaults(func=run_repair)


def run_repair(args: argparse.Namespace) -> int:
    done = [repair(f) for f in args.file]
    if args.json:
        print(json.dumps([{"path": str(d.path), "frames": d.frames,
                           "bytes_dropped": d.bytes_dropped,
                           "declared_frames": d.declared_frames} for d in done]))
    else:
        for d in done:
            print(d.describe())
    return 0
