"""``handrig record repair FILE``: make a take cut short by a crash readable;
``handrig record convert IN OUT``: a take in the other format, or a BVH at another rate."""

from __future__ import annotations

import argparse
import json
from typing import Any

import numpy as np

from handrig.cli._numbers import positive_float
from handrig.errors import DataError
from handrig.outputs.recorder import Recorder, format_of, load_performance, repair


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "record",
        help="recordings made by `handrig run --record`: repair a take cut short, convert",
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
    c: argparse.ArgumentParser = actions.add_parser(
        "convert",
        help="write a take in the other format, or a BVH at another frame rate",
        description="Read a take (.csv or .bvh) and write it to OUT (.csv or .bvh, never"
        " replacing a file). A CSV keeps each frame's time; a BVH is written at a fixed"
        " frame rate, resampled from the frames' times (each BVH frame holds the frame"
        " due up to half a frame after its time), so the take keeps its length.",
    )
    c.add_argument("take", help="the take to read: TAKE.csv or TAKE.bvh")
    c.add_argument("out", help="the file to write: OUT.csv or OUT.bvh (must not exist)")
    c.add_argument("--rate", type=positive_float, default=None, metavar="HZ",
                   help="BVH frames per second (default: the take's own rate: a BVH's"
                   " frame rate, a CSV's median frame rate)")
    c.add_argument("--json", action="store_true", help="print what was done as JSON")
    c.set_defaults(func=run_convert)


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


def run_convert(args: argparse.Namespace) -> int:
    t_s, poses, wrist = load_performance(args.take)
    format_of(args.out)  # an unknown suffix fails before anything is written
    rate = args.rate
    if rate is None:
        steps = np.diff(t_s)
        steps = steps[steps > 0]
        if steps.size == 0:
            raise DataError(f"{args.take}: a single frame has no rate; give --rate HZ")
        rate = float(1.0 / np.median(steps))
    if not 1.0 <= rate <= 2000.0:
        raise DataError(f"--rate {rate:g}: use 1..2000 frames per second")
    with Recorder(args.out, rate_hz=rate, with_wrist=wrist is not None, sync=False) as rec:
        for i in range(len(t_s)):
            rec.add(float(t_s[i]), poses[i], None if wrist is None else wrist[i])
    done = {"take": str(args.take), "out": str(rec.path), "frames_in": len(t_s),
            "frames_out": rec.frames_written, "rate_hz": round(rate, 6),
            "duration_s": round(rec.duration_s, 6)}
    if args.json:
        print(json.dumps(done))
    else:
        print(f"{done['out']}: {done['frames_out']} frames from {done['frames_in']}"
              f" ({done['duration_s']:.3f} s" + (f", {rate:g} frames/s)" if rec.fmt == "bvh"
                                                 else ")"))
    return 0
