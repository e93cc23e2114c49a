"""``handrig record repair FILE``: make a take cut short by a crash readable;
``handrig record convert IN OUT``: a take in the other format, or a BVH at another rate;
``handrig record glove OUT.csv``: a glove take, what the glove sent with its arrival times."""

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
        help="takes: record a glove take, repair a take cut short, convert",
        description="Takes: record what a glove sends (a glove take), repair a take cut"
        " short, convert a performance take (`handrig run --record`) to the other format.",
    )
    actions = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    r: argparse.ArgumentParser = actions.add_parser(
        "repair",
        help="check every frame of a take and keep the whole ones (crash, kill, power cut,"
        " damage)",
        description="A take (a performance, CSV or BVH, or a glove take) is written to"
        " TAKE.partial while the show runs and renamed to TAKE when the run ends. After a"
        " crash, repair TAKE.partial (or TAKE): every frame is checked (its values are"
        " numbers, as many as the header says, its time comes after the last), an"
        " unfinished last line is cut, and a damaged line stops the take there: the whole"
        " frames before it are kept and the rest is moved to TAKE.damaged. A BVH header"
        " gets the frame count, and TAKE.partial becomes TAKE (unless TAKE exists). Safe"
        " to run on a whole file.",
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
    g: argparse.ArgumentParser = actions.add_parser(
        "glove",
        help="record what the glove sends, with arrival times (a glove take)",
        description="Store every good frame the glove sends (raw channels, forearm"
        " quaternion, buttons) with the time its last byte arrived, until --seconds or"
        " Ctrl-C/SIGTERM. No servos are needed. `handrig run --glove replay:OUT.csv` (or"
        " `handrig play OUT.csv --bus PORT`) plays it back through the whole pipeline at"
        " those times. OUT is never replaced.",
    )
    g.add_argument("out", help="the glove take to write: OUT.csv (must not exist)")
    g.add_argument("--glove", default=None, metavar="SPEC",
                   help="PORT (handrig frames), opengloves:PORT or replay:FILE.csv (default:"
                   " the glove file's port)")
    g.add_argument("--glove-config", default=None, metavar="FILE",
                   help="glove file (default: your calibrated glove.toml, else"
                   " config/glove.toml): its port, format, rate and channel names")
    g.add_argument("--seconds", type=positive_float, default=None, metavar="S",
                   help="stop after S s (default: at Ctrl-C)")
    g.add_argument("--json", action="store_true", help="print what was done as JSON")
    g.set_defaults(func=run_glove)


def run_repair(args: argparse.Namespace) -> int:
    done = [repair(f) for f in args.file]
    if args.json:
        print(json.dumps([{"path": str(d.path), "kind": d.kind, "frames": d.frames,
                           "bytes_dropped": d.bytes_dropped,
                           "declared_frames": d.declared_frames,
                           "damage": None if d.damage is None else {
                               "line": d.damage.line, "byte": d.damage.byte,
                               "what": d.damage.what, "moved_to": str(d.damage.moved_to),
                               "bytes_moved": d.damage.bytes_moved}} for d in done]))
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


def run_glove(args: argparse.Namespace) -> int:
    from handrig.app.glove_take_session import record_glove_take

    done = record_glove_take(args.out, glove=args.glove, glove_file=args.glove_config,
                             seconds=args.seconds)
    if args.json:
        print(json.dumps(done))
    else:
        print(f"{done['out']}: {done['frames']} glove frames in {done['duration_s']:.3f} s"
              f" from {done['glove']} ({done['errors']} bad frames)"
              + (f"; stopped by {done['stopped_by']}" if done["stopped_by"] else ""))
    return 0
