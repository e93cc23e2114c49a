"""``handrig sim-bus``: emulated Dynamixel servos (and a MuJoCo puppet) on a pty.

The first line of output is ``port: /dev/pts/N``; any Dynamixel client can open
that path. Serves until SIGINT or SIGTERM, then prints a summary and exits 0.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import threading
import time
from types import FrameType
from typing import Any, TextIO

from handrig.cli._numbers import whole_int
from handrig.config.rig import hand_rig
from handrig.errors import ConfigError, HandrigError
from handrig.pose.robot_rig import load_rig

REPORT_EVERY_S = 10.0


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "sim-bus",
        help="serve emulated Dynamixel X-series servos on a pty (MuJoCo hand loopback)",
        description="Emulated Dynamixel Protocol 2.0 bus on a pseudo-terminal. Prints "
        "'port: /dev/pts/N' first, serves until SIGINT/SIGTERM.",
    )
    who = p.add_mutually_exclusive_group()
    who.add_argument("--servos", type=whole_int, metavar="N",
                     help="servos with IDs 1..N (default: the rig's servos)")
    who.add_argument("--ids", metavar="LIST", help="servo IDs, e.g. '1,2,5' or '1-16,20'")
    p.add_argument("--rig", default=None, metavar="NAME|FILE",
                   help="rig preset (e.g. 'leap': the LEAP hand's model) or rig file "
                   "(default config/rig.toml): which ID drives which joint")
    p.add_argument("--model", default=None, metavar="NAME",
                   help="servo model for every servo (XL330-M288, XL330-M077, XC330-M288, "
                   "XC330-T288, XM430-W350, XC430-W150, XC430-T240BB; "
                   "default: the rig's)")
    p.add_argument("--servo-baud", default="", metavar="ID:BAUD,...",
                   help="servos at a baud other than the rig's, e.g. '1:57600,2:115200,"
                   "3:1000000'; a servo answers only at its own Baud Rate")
    p.add_argument("--wire-timing", action="store_true",
                   help="delay replies by their wire time at the baud the client set, "
                   "plus Return Delay Time")
    p.add_argument("--faults", default="", metavar="SPEC",
                   help="e.g. 'drop=0.02,corrupt=0.01,wrong_id=0.01,truncate=0.01,"
                   "delay=0.01:0.005,missing=7,overload=3@1.5,seed=1'")
    p.add_argument("--no-puppet", action="store_true",
                   help="no MuJoCo hand: servos move kinematically at their speed limit")
    p.add_argument("--viewer", action="store_true", help="show the puppet (needs a display)")
    p.add_argument("--hand", choices=("ri", "le"), default=None,
                   help="only this hand's servos, on its bus (a two-hand rig on two buses: "
                   "the left hand's at [left_bus]'s baud)")
    p.add_argument("--no-realtime", action="store_true",
                   help="do not ask for SCHED_FIFO priority for the bus thread")
    p.set_defaults(func=run)


def parse_ids(text: str) -> list[int]:
    """'1,2,5' or '1-16,20' -> IDs; raises ConfigError on anything else."""
    out: list[int] = []
    for part in filter(None, (p.strip() for p in text.split(","))):
        lo, dash, hi = part.partition("-")
        try:
            ids = range(int(lo), int(hi) + 1) if dash else [int(lo)]
        except ValueError:
            raise ConfigError("not an ID or range", file="--ids", key=part,
                              allowed="IDs 0..252 as '1,2,5' or '1-16'") from None
        for i in ids:
            if not 0 <= i <= 252:
                raise ConfigError("servo ID out of range", file="--ids", key=part, value=i,
                                  allowed="0..252")
            if i in out:
                raise ConfigError("servo ID given twice", file="--ids", key=part, value=i)
            out.append(i)
    if not out:
        raise ConfigError("no servo IDs given", file="--ids", allowed="e.g. '1-16'")
    return out


def parse_servo_bauds(text: str, ids: list[int]) -> dict[int, int]:
    """'1:57600,2:115200' -> {1: 57600, 2: 115200}; ConfigError on anything else
    (an ID not on the bus, a baud no X-series servo has)."""
    from firmware_protocol.dynamixel import INDEX_BY_BAUD

    allowed = "ID:BAUD pairs, e.g. '1:57600,2:1000000'; bauds " + ", ".join(
        str(b) for b in INDEX_BY_BAUD)
    out: dict[int, int] = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        sid, colon, baud = part.partition(":")
        try:
            servo_id, rate = int(sid), int(baud)
        except ValueError:
            raise ConfigError("not ID:BAUD", file="--servo-baud", key=part,
                              allowed=allowed) from None
        if not colon:
            raise ConfigError("not ID:BAUD", file="--servo-baud", key=part, allowed=allowed)
        if servo_id not in ids:
            raise ConfigError("no servo with this ID on the bus", file="--servo-baud",
                              key=part, value=servo_id,
                              allowed=",".join(str(i) for i in ids))
        if rate not in INDEX_BY_BAUD:
            raise ConfigError("not a Dynamixel X baud rate", file="--servo-baud", key=part,
                              value=rate, allowed=allowed)
        if servo_id in out:
            raise ConfigError("servo ID given twice", file="--servo-baud", key=part,
                              value=servo_id)
        out[servo_id] = rate
    return out


def _has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def run(args: argparse.Namespace) -> int:
    from firmware_protocol.dynamixel import MODELS
    from handrig.app import simulator
    rig = load_rig(args.rig)
    if args.hand is not None:
        rig = hand_rig(rig, args.hand)
    ids: list[int] | None = None
    if args.servos is not None:
        if not 1 <= args.servos <= 253:
            raise ConfigError("servo count out of range", file="--servos", value=args.servos,
                              allowed="1..253")
        ids = list(range(1, args.servos + 1))
    elif args.ids:
        ids = parse_ids(args.ids)
    if args.model is not None:
        if args.model not in MODELS:
            raise ConfigError("unknown servo model", file="--model", value=args.model,
                              allowed=", ".join(MODELS))
        rig = simulator.with_model(rig, args.model)
    bauds = parse_servo_bauds(args.servo_baud, ids if ids is not None
                              else [s.id for s in rig.servos])

    behind: list[float] = []
    bus, puppet = simulator.servo_bus(
        rig, ids=ids, model=args.model, puppet=not args.no_puppet, on_behind=behind.append,
        wire_timing=args.wire_timing, faults=args.faults, realtime=not args.no_realtime,
        bauds=bauds)
    stop = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop.set()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        bus.start()
        print(f"port: {bus.port_path}", flush=True)
        driven = set(puppet.driven_ids) if puppet is not None else set()
        models = sorted({s.info.name for s in bus.servos})
        rates = sorted({s.baud for s in bus.servos})
        _say(f"servos: {len(bus.servos)} ({', '.join(models)}), IDs "
             f"{','.join(str(s.id) for s in bus.servos)}; baud "
             f"{', '.join(str(r) for r in rates)}; puppet drives {len(driven)}; "
             f"wire timing {'on' if args.wire_timing else 'off'}; "
             f"faults {args.faults or 'none'}")
        viewer = _open_viewer(puppet) if args.viewer else None
        reported, reported_at = 0, -REPORT_EVERY_S
        while not stop.wait(1.0 / 30.0 if viewer is not None else 0.25):
            if bus.error is not None:
                raise HandrigError(f"emulated bus stopped: {bus.error!r}")
            now = time.monotonic()
            if len(behind) > reported and now - reported_at >= REPORT_EVERY_S:
                # rate-limited: a parent that never reads stderr must not fill the pipe
                _say(f"sim-bus: physics fell behind wall time {len(behind)} times "
                     f"({sum(behind) * 1000:.0f} ms skipped in all)", sys.stderr)
                reported, reported_at = len(behind), now
            if viewer is not None and puppet is not None:
                with puppet.physics_lock:
                    viewer.sync()
                if not viewer.is_running():
                    viewer = None
    finally:
        bus.stop()
        for s, h in old.items():
            signal.signal(s, h)
    st = bus.stats
    faults_seen = ", ".join(f"{k} {v}" for k, v in sorted(bus.fault_counts.items())) or "none"
    _say(f"sim-bus: {st.packets} packets, {st.replies} replies, {st.bad_crc} bad CRC; "
         f"{st.overhead_line()}; replies late by mean {st.late_mean_s * 1e6:.0f} us, "
         f"max {st.late_max_s * 1e6:.0f} us; faults: {faults_seen}; goals: "
         f"{st.goals_decoded} decoded, {st.goals_outside} outside the rig's limits")
    return 0


def _say(text: str, stream: TextIO | None = None) -> None:
    """Print and flush; a reader that stopped listening (closed pipe) is not an error."""
    with contextlib.suppress(BrokenPipeError, ValueError):
        print(text, file=stream or sys.stdout, flush=True)


def _open_viewer(puppet: Any) -> Any:
    if not _has_display():
        print("viewer: unavailable (no display: DISPLAY and WAYLAND_DISPLAY are unset); "
              "serving without it", file=sys.stderr, flush=True)
        return None
    if puppet is None or not puppet.hands:
        print("viewer: unavailable (no puppet to show)", file=sys.stderr, flush=True)
        return None
    try:
        import mujoco.viewer

        hand = next(iter(puppet.hands.values()))
        return mujoco.viewer.launch_passive(hand.model, hand.data)
    except Exception as exc:  # any viewer failure: serve without it
        print(f"viewer: unavailable ({exc}); serving without it", file=sys.stderr, flush=True)
        return None
