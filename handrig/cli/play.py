"""``handrig play FILE``: play a recorded performance (CSV or BVH) to a VMC receiver."""

from __future__ import annotations

import argparse
import json
from typing import Any

from handrig.cli._numbers import positive_float
from handrig.clock import MonotonicClock
from handrig.errors import ConfigError
from handrig.outputs.recorder import Playback
from handrig.outputs.vmc import DEFAULT_PORT, VmcSender, parse_host_port


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "play",
        help="play a recorded performance (.csv/.bvh) to a VMC receiver (no servos needed)",
        description="Play a performance recorded by `handrig run --record` (or a Perception"
        " Neuron BVH capture) to a VMC receiver such as VSeeFace, EVMC4U (Unity) or VMC4B"
        " (Blender), at the recorded times.",
    )
    p.add_argument("file", help="recording: .csv or .bvh")
    p.add_argument("--vmc", default=f"127.0.0.1:{DEFAULT_PORT}", metavar="HOST:PORT",
                   help=f"VMC receiver (default 127.0.0.1:{DEFAULT_PORT})")
    p.add_argument("--rate", type=positive_float, default=60.0, metavar="HZ",
                   help="VMC bundles per second (default 60)")
    p.add_argument("--speed", type=positive_float, default=1.0,
                   help="time scale, 2 = twice as fast")
    p.add_argument("--loop", action="store_true", help="start over at the end (until Ctrl-C)")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    host, port = parse_host_port(args.vmc)
    if not 0 < args.rate <= 1000:
        raise ConfigError("VMC rate out of range", key="--rate", value=args.rate,
                          allowed="0 < HZ <= 1000, e.g. 60")
    clock = MonotonicClock()
    playback = Playback(args.file, clock, speed=args.speed, loop=args.loop)
    if not args.json:  # the files in use, as run and demo print them
        print(f"files in use:\n  recording  {args.file}  (argument; it holds the joint angles: "
              "no rig, glove, map or sag grid is read)", flush=True)
    period_s = 1.0 / args.rate
    interrupted = False
    with VmcSender(host, port, rate_hz=args.rate, clock=clock) as sender:
        playback.start()
        next_s = clock.now()
        try:
            while (frame := playback.sample()) is not None:
                pose, wrist = frame
                sender.send(pose, wrist, playback.elapsed_s())
                next_s += period_s
                clock.sleep_until(next_s)
        except KeyboardInterrupt:  # the way to stop --loop; still print what was sent
            interrupted = True
        summary = {
            "file": str(args.file), "frames": playback.n_frames,
            "duration_s": round(playback.duration_s / args.speed, 3),
            "vmc": f"{host}:{port}", "rate_hz": args.rate,
            "bundles_sent": sender.bundles_sent, "errors": sender.errors,
            "wrist": playback.wrist is not None, "interrupted": interrupted,
        }
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"played {summary['file']}: {summary['frames']} frames,"
              f" {summary['duration_s']} s, {sender.bundles_sent} VMC bundles to"
              f" {host}:{port} at {args.rate:g} Hz, {sender.errors} errors"
              + (f" (last: {sender.last_error})" if sender.errors else "")
              + (" (interrupted)" if interrupted else ""))
    return 0 if sender.errors == 0 else 1
