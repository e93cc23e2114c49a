"""``handrig run``: the live rig, glove in, servos (or the simulated puppet) out."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from handrig.app.port_processes import SIM_BUS, StartedEmulators, sim_bus_argv
from handrig.app.view import add_view_flag
from handrig.cli._cues import add_cue_flags, cue_options
from handrig.cli._display import check_display, check_gl_backend
from handrig.cli._layers import add_layer_flag, layer_options
from handrig.cli._numbers import float_in, positive_float, positive_int
from handrig.cli._ports import say_if_simulated
from handrig.cli._rig import add_rig_argument, print_sources
from handrig.cli._timecode import add_ltc
from handrig.config.show import ShowFile, load_show
from handrig.errors import ConfigError, HandrigError

if TYPE_CHECKING:
    from handrig.app.cues.live import CueOptions
    from handrig.app.hands import SessionParts
    from handrig.app.sources import Source


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "run", help="run the live rig: glove -> full hands with sag -> servos",
        description="Run the live rig. On a terminal a live panel shows the glove link, "
        "latency, bus health, each servo and the outputs, and keys act on the puppet: "
        "space relaxes it (and resumes), q stops (eases to relaxed, then torque off), e is "
        "the e-stop (torque off at once). Without a terminal the panel is a plain line "
        "every few seconds. Ctrl-C, SIGTERM, SIGHUP or SIGQUIT eases the puppet to its "
        "relaxed pose, then disables torque; a second one stops at once. --seconds and "
        "--frames count the run before the ease to relaxed, which the summary includes.",
    )
    add_rig_argument(p)
    p.add_argument("--show", default=None, metavar="FILE.toml",
                   help="a show file naming the rig, gloves, map, grid, buses and outputs "
                   "(examples/show.toml); flags given here win over it")
    p.add_argument("--glove-config", default=None, metavar="FILE",
                   help="glove file (default: the rig file's [loop] glove, else your calibrated "
                   "glove.toml, else config/glove.toml)")
    p.add_argument("--glove", default=None, metavar="SPEC",
                   help="PORT (handrig frames), opengloves:PORT, or replay:FILE.csv (with "
                   "--glove-left: the right hand's glove)")
    p.add_argument("--glove-left", default=None, metavar="SPEC",
                   help="the left hand's glove, as --glove takes it: a rig with servos for "
                   "both hands (e.g. --rig puppet_two_hands) then drives each hand from its "
                   "own glove, with the two-glove map (default: the rig file's [gloves] left)")
    p.add_argument("--glove-left-config", default=None, metavar="FILE",
                   help="the left glove's glove file (default: [gloves] left_config, else "
                   "the right glove's)")
    p.add_argument("--bus", "--port", dest="bus", default=None, metavar="PORT",
                   help="servo port, or 'sim' for the simulated rig (the MuJoCo loopback); "
                   "default: the rig file's [bus] port (the shipped rig names none)")
    p.add_argument("--bus-left", default=None, metavar="PORT",
                   help="a rig on two buses ([left_bus]): the left hand's servo port, or "
                   "'sim' (default: [left_bus] port)")
    p.add_argument("--viewer", action="store_true",
                   help="with --bus sim: show the simulated puppet (needs a display)")
    p.add_argument("--vmc", default=None, metavar="HOST:PORT",
                   help="also send the hands to a VMC receiver (VSeeFace, Unity, Blender)")
    p.add_argument("--openxr", default=None, metavar="HOST:PORT",
                   help="also send both hands as the 26 OpenXR hand joints each, over UDP "
                   "(docs/openxr.md; e.g. 127.0.0.1:39540)")
    p.add_argument("--record", default=None, metavar="FILE",
                   help="record the performance (.csv or .bvh; never replaces a file)")
    p.add_argument("--record-glove", default=None, metavar="FILE.csv",
                   help="also store what the glove sent, each frame with its arrival time"
                   " (a glove take: --glove replay:FILE.csv plays it; never replaces a file)")
    p.add_argument("--record-glove-left", default=None, metavar="FILE.csv",
                   help="with --glove-left: store what the left glove sent (--record-glove"
                   " then stores the right glove's)")
    p.add_argument("--record-rate", type=float_in(1.0, 2000.0), default=None, metavar="HZ",
                   help="a .bvh take's frames per second (default: the glove's [glove]"
                   " rate_hz; a CSV keeps each frame's own time)")
    add_ltc(p)
    p.add_argument("--frames", type=positive_int, default=None, metavar="N",
                   help="stop after N cycles")
    p.add_argument("--seconds", type=positive_float, default=None, metavar="S",
                   help="stop after S s")
    p.add_argument("--no-wire-timing", action="store_true",
                   help="with --bus sim: answer instantly instead of at the wire's speed")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    add_layer_flag(p)
    add_view_flag(p)
    add_cue_flags(p)
    p.set_defaults(func=run)


def _from_show(args: argparse.Namespace) -> ShowFile | None:
    """Fill the flags not given from ``--show``'s file (None without one)."""
    if not args.show:
        return None
    show = load_show(args.show)
    fill = {"rig": show.show.rig, "glove": show.gloves.right, "glove_left": show.gloves.left,
            "glove_config": show.gloves.right_config,
            "glove_left_config": show.gloves.left_config, "bus": show.buses.right,
            "bus_left": show.buses.left, "vmc": show.outputs.vmc, "openxr": show.outputs.openxr,
            "record": show.outputs.record, "record_rate": show.outputs.record_rate_hz,
            "view": show.outputs.view, "ltc": show.timecode.source,
            "ltc_fps": show.timecode.fps}
    # the cue flags ([osc], [midi], [cues]) are filled by handrig.cli._cues.cue_options
    filled = []
    for name, value in fill.items():
        if getattr(args, name) is None and value:
            setattr(args, name, value)
            filled.append(name)
    args.from_show = filled
    return show


def _show_sources(sources: list[Source], show: ShowFile, filled: list[str]) -> list[Source]:
    """The files a show named, said to come from it (not from --rig or the rig file)."""
    from handrig.app.sources import Source
    why = f"the show's, {show.path}"
    out = []
    for s in sources:
        if s.role == "rig" and "rig" in filled:
            s = Source("rig", s.path, why)
        elif s.role == "glove" and "glove_config" in filled:
            s = Source("glove", s.path, why)
        elif s.role == "map" and show.show.map:
            s = Source("map", Path(show.show.map), why)
        elif s.role == "sag grid" and show.show.grid:
            s = Source("sag grid", Path(show.show.grid), why)
        out.append(s)
    return out


def run(args: argparse.Namespace) -> int:
    with StartedEmulators() as started:  # one the session did not take: stopped on the way
        try:
            show = _from_show(args)
            cues = cue_options(args, show)  # said before an emulator starts
            if args.viewer:
                check_display("--viewer")
            _start_sim_bus(args, started)
        except HandrigError as exc:
            if not args.json:
                raise
            from handrig.app.result import failed, print_result

            return print_result(failed(exc), as_json=True)
        return _run(args, show, started, cues)


def _start_sim_bus(args: argparse.Namespace, started: StartedEmulators) -> None:
    """Start the simulated bus of a one-bus rig whose bus is ``sim`` now, before this
    process imports the run's modules and builds the map's kernels, so that the
    emulator's start-up (MuJoCo puppet, pty) overlaps them; the session takes it
    (by its arguments) where it would start one. A rig with a left bus: none started."""
    from handrig.config.rig import require_port
    from handrig.pose.robot_rig import find_rig

    rig_file, rig = find_rig(args.rig)
    # no port: said before the run's imports and kernels (a left bus's port once the hand
    # flags are checked: a rig on two buses needs a glove per hand first)
    require_port(args.bus or rig.bus.port, rig_file)
    if rig.left_bus is None and (args.bus or rig.bus.port) == "sim":
        started.start(sim_bus_argv(rig_file, None, wire_timing=not args.no_wire_timing,
                                   viewer=args.viewer), SIM_BUS)


def _run(args: argparse.Namespace, show: ShowFile | None, started: StartedEmulators,
         cues: CueOptions | None) -> int:
    from handrig.app.hands import build_session_parts, glove_specs
    from handrig.app.result import failed, print_result
    from handrig.app.session import LiveOptions, run_live
    from handrig.app.sources import run_sources, session_sources
    from handrig.app.timecode import check_stamp_path, open_reader
    from handrig.app.view import view_session
    from handrig.clock import MonotonicClock
    from handrig.config.rig import require_port
    from handrig.pose.robot_rig import find_rig

    try:
        files = ({"map_file": show.show.map or None, "grid_file": show.show.grid or None}
                 if show is not None else {})
        _, rig = find_rig(args.rig)
        right, left = glove_specs(rig, args.glove, args.glove_left)
        _check_hand_flags(args, rig.left_bus is not None, left)
        parts: SessionParts = build_session_parts(
            args.rig, args.glove_config, args.glove_left_config,
            glove_per_hand=left is not None, **files)
        bus = require_port(args.bus or rig.bus.port, parts.rig_file)
        bus_left = (require_port(args.bus_left or rig.left_bus.port, parts.rig_file,
                                 flag="--bus-left") if rig.left_bus is not None else "")
        if "sim" in (bus, bus_left):
            check_gl_backend("--bus sim")
        layering = layer_options(args, show)
        reader = None
        if args.ltc:  # opened now: a bad source or an existing stamps file stops us here
            check_stamp_path(args.record)
            reader = open_reader(args.ltc, MonotonicClock(), fps=args.ltc_fps or "auto")
    except HandrigError as exc:
        if not args.json:
            raise
        return print_result(failed(exc), as_json=True)
    if not args.json:
        say_if_simulated(bus) or say_if_simulated(bus_left)
        if show is not None:
            _stderr(f"show: {show.title} ({show.path})")
        sources = session_sources(
            parts, run_sources(args.rig, args.glove_config, parts.rig_config))
        if show is not None:
            sources = _show_sources(sources, show, args.from_show)
        print_sources(sources)
    with view_session(args.view, parts.rig_config, _stderr) as view:
        opts = LiveOptions(
            glove=right, bus=args.bus, frames=args.frames, duration_s=args.seconds,
            wire_timing=not args.no_wire_timing, viewer=args.viewer, vmc=args.vmc,
            openxr=args.openxr, record=args.record, record_rate_hz=args.record_rate,
            record_glove=args.record_glove, record_glove_left=args.record_glove_left,
            panel=not args.json,
            verbose=not args.json, glove_left=left, bus_left=args.bus_left,
            show=show.title if show is not None else "",
            on_hands=view.attach_hands if view is not None else None, started=started,
            cues=cues,
            layering=layering,
            timecode=reader,
        )
        result = run_live(parts, opts)
    if result.error is not None and not result.started and not args.json:
        raise result.error
    return print_result(result, as_json=args.json)


def _check_hand_flags(args: argparse.Namespace, left_bus: bool, left: str | None) -> None:
    """The flags of a glove per hand against the rig: ConfigError naming the flag."""
    if left is None and left_bus:
        raise ConfigError(
            "this rig has the left hand's servos on a bus of their own: it needs a "
            "glove per hand", key="--glove-left", file=None,
            allowed="--glove-left PORT (or [gloves] left in the rig file)")
    if left is None and args.record_glove_left is not None:
        raise ConfigError("a left glove take needs a glove per hand",
                          key="--record-glove-left", value=args.record_glove_left,
                          allowed="--glove-left PORT, or --record-glove for one glove")
    if left is None and args.bus_left is not None:
        raise ConfigError("a left bus needs a rig with [left_bus] and a glove per hand",
                          key="--bus-left", value=args.bus_left,
                          allowed="--rig puppet_two_buses --glove-left PORT")


def _stderr(text: str) -> None:
    print(text, file=sys.stderr, flush=True)
