"""``handrig play TAKE``: play a take onto the servos (``--bus PORT|sim``) through the
live loop, with the live show's safety; without ``--bus``, a performance (CSV or BVH)
to a VMC receiver only (and, with ``--openxr``, the OpenXR hand joints)."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from typing import TYPE_CHECKING, Any

import numpy as np

from handrig.app.parts import build_parts, check_outputs
from handrig.app.result import failed, print_result
from handrig.app.session import LiveOptions, run_live
from handrig.app.sources import Source, run_sources
from handrig.app.takes import load_play_take, play_parts, take_kind
from handrig.app.timecode import chase_setup
from handrig.app.view import add_view_flag, view_playback, view_session
from handrig.cli._cues import add_cue_flags, cue_options
from handrig.cli._display import check_gl_backend
from handrig.cli._layers import add_layer_flag, layer_options
from handrig.cli._numbers import nonnegative_float, positive_float
from handrig.cli._ports import say_if_simulated
from handrig.cli._rig import add_rig_argument, print_sources
from handrig.cli._timecode import add_chase
from handrig.clock import MonotonicClock
from handrig.errors import ConfigError, DataError, HandrigError
from handrig.outputs.recorder import Playback
from handrig.outputs.vmc import DEFAULT_PORT, VmcSender, parse_host_port

if TYPE_CHECKING:
    from handrig.outputs.openxr import OpenXrSender


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "play",
        help="play a take onto the servos (--bus PORT|sim) or to a VMC receiver",
        description="Play a take: a performance recorded by `handrig run --record` (.csv or"
        " .bvh, or a Perception Neuron BVH capture) or a glove take (`handrig run"
        " --record-glove`, `handrig record glove`). With --bus it plays onto the rig"
        " through the live loop with the live show's safety: torque on only while it"
        " plays, every goal inside the joint and servo limits and the slew limit, an ease"
        " in from where the servos are and out to the relaxed pose at the end, the same"
        " keys and panel as `handrig run` (space relaxes, q stops, e is the e-stop);"
        " Ctrl-C, SIGTERM, SIGHUP or SIGQUIT eases to relaxed and turns torque off. A take"
        " that does not fit the rig (another vocabulary, a different number of curves or"
        " glove channels, cut short, times going backwards) is refused before the bus is"
        " opened. Without --bus a performance goes to a VMC receiver only (VSeeFace, EVMC4U,"
        " VMC4B), no servos needed.",
    )
    p.add_argument("file", help="the take: a performance .csv/.bvh or a glove take .csv")
    p.add_argument("--bus", "--port", dest="bus", default=None, metavar="PORT",
                   help="play onto the servos on PORT, or 'sim' for the MuJoCo loopback")
    add_rig_argument(p)
    p.add_argument("--glove-config", default=None, metavar="FILE",
                   help="with --bus: the glove file a glove take is calibrated with (default"
                   " as `handrig run`); a performance uses its fixed [forearm] for the"
                   " relaxed pose")
    p.add_argument("--vmc", default=None, metavar="HOST:PORT",
                   help=f"VMC receiver (without --bus the default is 127.0.0.1:{DEFAULT_PORT};"
                   " with --bus only when given)")
    p.add_argument("--rate", type=positive_float, default=60.0, metavar="HZ",
                   help="without --bus: VMC bundles per second (default 60)")
    p.add_argument("--speed", type=positive_float, default=1.0,
                   help="time scale, 2 = twice as fast (0.05..20 with --bus)")
    p.add_argument("--from", dest="from_s", type=nonnegative_float, default=None,
                   metavar="S", help="with --bus: start S seconds into the take")
    p.add_argument("--to", dest="to_s", type=positive_float, default=None, metavar="S",
                   help="with --bus: end S seconds into the take")
    p.add_argument("--loop", action="store_true",
                   help="start over at the end, until stopped (an installation)")
    p.add_argument("--no-wire-timing", action="store_true",
                   help="with --bus sim: answer instantly instead of at the wire's speed")
    add_chase(p)
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.add_argument("--openxr", default=None, metavar="HOST:PORT",
                   help="also send both hands as the 26 OpenXR hand joints each, over UDP "
                   "(docs/openxr.md; e.g. 127.0.0.1:39540)")
    add_layer_flag(p)
    add_view_flag(p)
    add_cue_flags(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.bus is not None:
        return run_on_rig(args)
    for flag, value in (("--from", args.from_s), ("--to", args.to_s),
                        ("--glove-config", args.glove_config), ("--osc-in", args.osc_in),
                        ("--midi-in", args.midi_in), ("--cue-takes", args.cue_takes),
                        ("--layer", args.layer), ("--chase-ltc", args.chase_ltc)):
        if value is not None:
            raise ConfigError("only with --bus", key=flag, value=value,
                              allowed="add --bus PORT (or --bus sim) to play onto the rig")
    if take_kind(args.file) == "glove":
        raise DataError(f"{args.file}: a glove take goes through the rig's pipeline: play it"
                        f" with `handrig play {args.file} --bus PORT` (or --bus sim), adding"
                        " --vmc HOST:PORT for a virtual puppet too")
    return run_to_vmc(args)


def run_on_rig(args: argparse.Namespace) -> int:
    """The take onto the servos through the live session (:func:`run_live`)."""
    try:
        parts = build_parts(args.rig, args.glove_config)
        take = load_play_take(args.file, parts.glove_config, speed=args.speed,
                              from_s=args.from_s, to_s=args.to_s,
                              glove_file=parts.glove_file)
        parts = play_parts(parts, take)
        if args.bus == "sim":
            check_gl_backend("--bus sim")
        cues = cue_options(args)
        layering = layer_options(args)
        chase = chase_setup(args, take) if args.chase_ltc else None
    except HandrigError as exc:
        if not args.json:
            raise
        return print_result(failed(exc), as_json=True)
    if not args.json:
        say_if_simulated(args.bus)
        sources = run_sources(args.rig, args.glove_config, parts.rig_config)
        if take.kind == "performance":  # the take is the pose: no glove, map or sag for it
            relaxed = "only for the relaxed pose (a lost frame, a stop); the take is the pose"
            sources = [Source(s.role, s.path, f"{relaxed}; {s.why}")
                       if s.role in ("map", "sag grid") else
                       Source(s.role, s.path, f"only its forearm angles, for the relaxed "
                              f"pose's sag; {s.why}") if s.role == "glove" else s
                       for s in sources]
        print_sources(sources)
        print(f"  take       {take.describe()}" + (", looped" if args.loop else ""),
              flush=True)
    rec = take.recording
    one_frame = float(rec.t_s[1] - rec.t_s[0]) if len(rec) > 1 else 0.01
    duration_s = None if args.loop else round(take.duration_s + one_frame, 3)
    if chase is not None:
        duration_s = chase.duration_s
    with view_session(args.view, parts.rig_config, _stderr) as view:
        opts = LiveOptions(
            glove=f"replay:{args.file}", take=lambda clock: take.source(clock, loop=args.loop)
            if chase is None else chase.glove(clock),
            timecode=chase.reader if chase is not None else None,
            bus=args.bus, duration_s=duration_s,
            wire_timing=not args.no_wire_timing, vmc=args.vmc, openxr=args.openxr,
            panel=not args.json,
            verbose=not args.json, on_hands=view.attach_hands if view is not None else None,
            done_reason=f"the take played ({take.duration_s:.2f} s)" if chase is None
            else "the timecode source ended", cues=cues, layering=layering)
        result = run_live(parts, opts)
    if chase is not None:
        chase.report(result.summary, as_json=args.json)
    if result.error is not None and not result.started and not args.json:
        raise result.error
    return print_result(result, as_json=args.json)


def _stderr(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def _openxr_sender(target: str | None, rate_hz: float, clock: MonotonicClock
                   ) -> contextlib.AbstractContextManager[OpenXrSender | None]:
    """``--openxr``'s sender beside VMC's (None without the flag)."""
    from handrig.outputs.openxr import OpenXrSender, parse_target

    if not target:
        return contextlib.nullcontext()
    check_outputs(None, None, target)
    return OpenXrSender(*parse_target(target), rate_hz=rate_hz, clock=clock)


def run_to_vmc(args: argparse.Namespace) -> int:
    """A performance to a VMC receiver only, at its recorded times."""
    if args.vmc is None:
        args.vmc = f"127.0.0.1:{DEFAULT_PORT}"
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
    with (VmcSender(host, port, rate_hz=args.rate, clock=clock) as sender,
          _openxr_sender(args.openxr, args.rate, clock) as xr,
          view_playback(args.view, str(args.file),
                        lambda text: print(text, file=sys.stderr, flush=True)) as view):
        playback.start()
        next_s = clock.now()
        try:
            while (frame := playback.sample()) is not None and not view.stop_requested:
                pose, wrist = frame
                sender.send(pose, wrist, playback.elapsed_s())
                if xr is not None:
                    xr(playback.elapsed_s(), np.concatenate(
                        [pose, wrist if wrist is not None else np.zeros(4)]))
                view.show(pose, wrist, playback.elapsed_s())
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
        if xr is not None:
            summary["openxr"] = xr.summary(playback.duration_s / args.speed)[1]
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"played {summary['file']}: {summary['frames']} frames,"
              f" {summary['duration_s']} s, {sender.bundles_sent} VMC bundles to"
              f" {host}:{port} at {args.rate:g} Hz, {sender.errors} errors"
              + (f" (last: {sender.last_error})" if sender.errors else "")
              + (" (interrupted)" if interrupted else ""))
    return 0 if sender.errors == 0 else 1
