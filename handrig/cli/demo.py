"""``handrig demo``: the embedded default run, no hardware and no display needed.

A glove recording shipped with handrig (the reference mocap's right-hand control
curves as raw sensor counts, plus a forearm path that sweeps the sag) streams
through the glove emulator on a pty, the real serial glove reader, the real
pipeline (calibration, One Euro filter, map expansion, sag, limits, slew) and the
real Dynamixel driver into ``handrig sim-bus``'s MuJoCo puppet, with wire timing
at the rig's baud rate. Prints a summary of what was measured.

``--rig puppet_two_hands`` (or ``puppet_two_buses``) runs both hands of the
two-hand puppet, each from an emulated glove of its own (the same recording, the
left glove starting ``--left-offset`` seconds into it), with the two-glove map:
on one bus at 4 Mbps, or on two buses at 1 Mbps.

``--rig leap`` (a robot rig preset, or any robot rig file) runs the same path
into the robot: the pipeline ends in the rig's retarget table, the emulated
servos are the rig's (XC330-M288s at 4 Mbps for LEAP) and the puppet is the
robot's MJCF model, which ``--render`` draws.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

from handrig.app.port_processes import SIM_BUS, PortProcess, StartedEmulators, sim_bus_argv
from handrig.app.view import add_view_flag
from handrig.cli._cues import add_cue_flags, cue_options
from handrig.cli._display import check_gl_backend, check_renderer
from handrig.cli._layers import add_layer_flag, layer_options
from handrig.cli._numbers import positive_float, positive_int
from handrig.cli._ports import SIMULATED_FIRST_LINE
from handrig.cli._rig import add_rig_argument
from handrig.errors import HandrigError

if TYPE_CHECKING:
    from handrig.app.layering import LayerOptions
    from handrig.config.rig import RigConfig

DEFAULT_FRAMES = 3000  # 15 s at 200 Hz
WIRE_TIMING = True  # the emulated bus answers at the rig's baud rate


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "demo", help="the embedded demo: a recorded glove drives the simulated puppet",
        description=__doc__,
    )
    add_rig_argument(p)
    p.add_argument("--frames", type=positive_int, default=None, metavar="N",
                   help=f"loop cycles to run (default {DEFAULT_FRAMES}, 15 s at 200 Hz)")
    p.add_argument("--seconds", type=positive_float, default=None, metavar="S",
                   help="run this long instead (with --frames: whichever ends first)")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.add_argument("--render", default=None, metavar="FILE.png",
                   help="also write an image strip of the simulated hand")
    p.add_argument("--recording", default=None, metavar="FILE.csv",
                   help="glove recording to stream (default config/recordings/demo_glove.csv)")
    p.add_argument("--glove-rate", type=positive_float, default=200.0, metavar="HZ",
                   help="rate the emulated glove sends at (default 200)")
    p.add_argument("--left-offset", type=positive_float, default=5.0, metavar="S",
                   help="a two-hand rig: the left glove starts this far into the recording "
                   "(default 5 s), so the hands do not move alike")
    p.add_argument("--faults", default="", metavar="SPEC",
                   help="switch on emulated bus faults (see handrig sim-bus --help)")
    p.add_argument("--openxr", default=None, metavar="HOST:PORT",
                   help="also send both hands as the 26 OpenXR hand joints each, over UDP "
                   "(docs/openxr.md; e.g. 127.0.0.1:39540)")
    add_layer_flag(p)
    add_view_flag(p)
    add_cue_flags(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from handrig.app import simulator
    from handrig.pose.robot_rig import find_rig

    recording = args.recording or str(simulator.demo_recording())
    layering = layer_options(args)  # a malformed --layer: said before anything starts
    check_gl_backend("the demo's simulated puppet")
    if args.render:
        check_renderer("--render")
    # The emulators start first, so that their start-ups (MuJoCo puppet, pty) overlap
    # this process's (its imports, the map's kernels); the session takes the bus's
    # (by its arguments) where it used to start it. Those not taken stop on the way out.
    rig_file, rig_cfg = find_rig(args.rig)
    with StartedEmulators() as started:
        for hand in _sim_bus_hands(rig_cfg):
            started.start(sim_bus_argv(rig_file, hand, wire_timing=WIRE_TIMING,
                                       faults=args.faults), SIM_BUS)
        with PortProcess(["sim-glove", recording, "--rate", f"{args.glove_rate:g}"],
                         "the glove emulator (handrig sim-glove)") as glove:
            return _run(args, recording, started, glove, layering)


def _run(args: argparse.Namespace, recording: str, started: StartedEmulators,
         glove: PortProcess, layering: LayerOptions) -> int:
    from handrig.app import simulator
    from handrig.app.hands import build_session_parts, is_two_hand
    from handrig.app.parts import robot_model
    from handrig.app.result import failed, print_result
    from handrig.app.session import LiveOptions, run_live
    from handrig.app.session_exit import ExitSignals
    from handrig.app.sources import Source, format_sources, run_sources
    from handrig.app.view import view_session
    from handrig.pose.robot_rig import find_rig, render_view

    def log(text: str) -> None:
        if not args.json:
            with contextlib.suppress(OSError, ValueError):  # the terminal may be gone
                print(text, flush=True)

    log(SIMULATED_FIRST_LINE)
    frames = args.frames if args.frames or args.seconds else DEFAULT_FRAMES
    # the render's snapshots: six over the run (the glove's nominal 200 frames a second)
    expected = frames or round(args.seconds * args.glove_rate)
    _, rig_cfg = find_rig(args.rig)
    parts = build_session_parts(args.rig, glove_per_hand=is_two_hand(rig_cfg))
    per_hand = len(parts.hands) > 1
    log(format_sources([*run_sources(args.rig, rig_cfg=parts.rig_config), Source(
        "recording", Path(recording), "--recording" if args.recording else
        "shipped demo: raw glove counts, calibrated with the glove file above")]))
    log(f"demo: {recording} -> glove emulator -> pipeline -> Dynamixel driver -> MuJoCo puppet")
    with (ExitSignals() as signals,  # a Ctrl-C while the glove emulator starts unwinds
          view_session(args.view, parts.rig_config,
                       lambda text: print(text, file=sys.stderr, flush=True)) as view):
        try:
            with contextlib.ExitStack() as gloves:
                glove_port = gloves.enter_context(glove).port()
                log(f"glove emulator streaming on {glove_port}")
                left_port = None
                if per_hand:
                    left = simulator.recording_from(recording, args.left_offset,
                                                    gloves.enter_context(
                                                        tempfile.TemporaryDirectory()))
                    left_port = gloves.enter_context(PortProcess(
                        ["sim-glove", str(left), "--rate", f"{args.glove_rate:g}"],
                        "the left glove's emulator (handrig sim-glove)")).port()
                    log(f"left glove emulator streaming on {left_port} ({recording} from "
                        f"{args.left_offset:g} s)")
                opts = LiveOptions(glove=glove_port, recorded=recording, bus="sim",
                                   frames=frames, duration_s=args.seconds,
                                   glove_left=left_port,
                                   bus_left="sim" if per_hand else None,
                                   sim_faults=args.faults, wire_timing=WIRE_TIMING,
                                   openxr=args.openxr,
                                   started=started, log=log, panel=not args.json,
                                   on_hands=view.attach_hands if view is not None else None,
                                   snapshot_every=max(1, expected // 6) if args.render else 0,
                                   cues=cue_options(args), layering=layering)
                signals.disarm()  # the session handles its own; after it: shut down, print
                result = run_live(parts, opts)
        except HandrigError as exc:
            result = failed(exc, parts)
    if result.error is not None and not result.started and not args.json:
        raise result.error
    if args.render and result.started:
        try:
            path = simulator.render_strip(result.snapshots, result.joint_names, args.render,
                                          model=robot_model(parts.rig_config),
                                          times_s=result.snapshot_times_s,
                                          view=render_view(parts.rig_config))
            result.summary["render"] = str(path)
            tiles = simulator.tiles_drawn(len(result.snapshots))
            log(f"rendered {tiles} frames of the simulated hand to {path} "
                f"(t = {result.snapshot_times_s[0]:.1f} to {result.snapshot_times_s[-1]:.1f} s)")
        except HandrigError as exc:
            result.summary["render"] = None
            print(f"handrig demo: no render: {exc}", file=sys.stderr)
    return print_result(result, as_json=args.json)


def _sim_bus_hands(rig: RigConfig) -> list[str | None]:
    """The ``--hand`` of each simulated bus the session opens for ``rig`` (None: the
    whole rig): a two-hand rig on two buses has one per hand."""
    from handrig.pose.robot_rig import is_two_hand

    if is_two_hand(rig) and rig.left_bus is not None:
        return ["ri", "le"]
    return [None]
