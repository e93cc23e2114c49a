"""``handrig retarget check``: a robot hand's retarget table against its inputs.

Prints the table (each robot joint's source curves with their gains, the offset
and the robot's range), then for each joint the range its sources reach: over the
human joint limits, over the shipped reference capture, and over the demo glove
recording expanded through the map, as the demo feeds it. Joints whose inputs
reach past the robot's range are flagged, and the share of demo frames clipped at
each robot limit is given. Exit status 1 when a joint is flagged (the capture or
the demo reaches past its range: the robot sits at a limit there), 0 when none is.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from handrig import hand
from handrig.config.loading import CONFIG_DIR, load_joint_limits
from handrig.errors import ConfigError
from handrig.pose.retarget import JointCheck, Retarget, check_joints, load_retarget

DEFAULT_RIG = "leap"
DEMO_RECORDING = CONFIG_DIR / "recordings" / "demo_glove.csv"


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "retarget", help="robot-hand retarget tables: human curves -> robot joints",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    c: argparse.ArgumentParser = actions.add_parser(
        "check", help="print the table, flag ranges past the robot's, count demo limit hits "
        "(exit 1 when a joint is flagged)",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    c.add_argument("--rig", default=DEFAULT_RIG,
                   help=f"robot rig preset or file (default {DEFAULT_RIG!r})")
    c.add_argument("--table", default=None, metavar="FILE.toml",
                   help="a retarget table to check instead of the rig's")
    c.add_argument("--recording", default=str(DEMO_RECORDING), metavar="FILE.csv",
                   help="glove recording for the limit counts (default: the demo's)")
    c.add_argument("--no-capture", action="store_true",
                   help="skip the reference capture (faster)")
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(func=run_check)

    def usage(args: argparse.Namespace) -> int:
        p.print_help()
        return 2

    p.set_defaults(func=usage)


def _rig_parts(args: argparse.Namespace) -> tuple[Retarget, Path, str, str]:
    """The retarget table, the rig's folder, its map and glove settings."""
    from handrig.app.robots import RobotRigConfig, load_rig, rig_path, robot_retarget

    if args.table is not None:
        return load_retarget(args.table), Path(args.table).resolve().parent, "", ""
    rig = load_rig(args.rig)
    if not isinstance(rig, RobotRigConfig):
        raise ConfigError("not a robot rig: it has no [robot] table with a retarget table",
                          file=str(rig_path(args.rig)),
                          allowed="a robot rig such as 'leap', or --table FILE")
    base = rig_path(args.rig).resolve().parent
    return robot_retarget(rig), base, rig.loop.map, rig.loop.glove


def _demo_poses(recording: str, base: Path, map_path: str, glove_path: str) -> np.ndarray:
    """The recording through the glove calibration, filter and map: (n, 50) degrees."""
    from handrig.devices.glove_calibration import GloveControls, load_glove_config
    from handrig.devices.glove_recording import read_glove_recording
    from handrig.pose.expand import DEFAULT_MAP, Expander

    ex = Expander.from_file(base / map_path if map_path else DEFAULT_MAP)
    cfg = load_glove_config(base / glove_path if glove_path else CONFIG_DIR / "glove.toml")
    controls = GloveControls.from_config(cfg, ex.controls)
    rec = read_glove_recording(recording)
    out = np.empty((len(rec), len(ex.controls)))
    for i in range(len(rec)):
        controls(rec.raw[i], float(rec.t_s[i]), out[i])
    poses: np.ndarray = ex.expand_many(out)
    return poses


def run_check(args: argparse.Namespace) -> int:
    rt, base, map_path, glove_path = _rig_parts(args)
    limits = load_joint_limits()
    bounds = np.array([limits.of(n) for n in hand.CURVE_NAMES], dtype=np.float64)
    capture = None
    if not args.no_capture:
        from handrig.offline.mocap import load_reference

        capture = load_reference().curves
    demo = _demo_poses(args.recording, base, map_path, glove_path)
    checks = check_joints(rt, bounds[:, 0], bounds[:, 1], capture, demo)
    flagged = any(set(c.flags) & {"capture", "demo"} for c in checks)
    if args.json:
        print(json.dumps(_as_json(rt, checks, len(demo))))
        return 1 if flagged else 0
    _print_table(rt)
    print()
    _print_checks(checks, len(demo), capture is not None)
    return 1 if flagged else 0


def _sources(rt: Retarget, k: int) -> str:
    parts = [f"{g:+g} {hand.CURVE_NAMES[c]}" for c, g in enumerate(rt.gain[k]) if g != 0.0]
    return " ".join(parts) if parts else "(none: held at the offset)"


def _print_table(rt: Retarget) -> None:
    notes = rt.table.joints if rt.table is not None else {}
    print(f"retarget table: {len(rt.joint_names)} robot joints, degrees; "
          "robot = clip(offset + sum gain x curve, range)")
    print(f"{'robot joint':<12} {'range':>16}  {'offset':>7}  sources")
    for k, name in enumerate(rt.joint_names):
        note = notes[name].note if name in notes else ""
        print(f"{name:<12} {rt.low_deg[k]:>7.1f} .. {rt.high_deg[k]:<6.1f} "
              f"{rt.offset_deg[k]:>7.1f}  {_sources(rt, k)}" + (f"  # {note}" if note else ""))


def _fmt(rng: tuple[float, float] | None) -> str:
    return "-" if rng is None else f"{rng[0]:.1f} .. {rng[1]:.1f}"


def _print_checks(checks: list[JointCheck], frames: int, with_capture: bool) -> None:
    print(f"what the sources reach (unclipped), and demo frames clipped at each limit "
          f"({frames} frames)")
    print(f"{'robot joint':<12} {'range':>16} {'anatomy':>16} {'capture':>16} {'demo':>16}"
          f" {'at low':>7} {'at high':>7} {'covers':>7}  flags")
    for c in checks:
        flags = ", ".join(f"{f} exceeds range" for f in c.flags) or "ok"
        print(f"{c.joint:<12} {_fmt(c.range_deg):>16} {_fmt(c.anatomical_deg):>16} "
              f"{_fmt(c.capture_deg):>16} {_fmt(c.demo_deg):>16} "
              f"{100 * c.demo_low_frac:>6.1f}% {100 * c.demo_high_frac:>6.1f}% "
              f"{_pct(c.demo_cover_frac):>7}  {flags}")
    flagged = [c.joint for c in checks if set(c.flags) & {"capture", "demo"}]
    print(f"{len(flagged)} of {len(checks)} robot joints get inputs past their range from "
          f"the {'capture or ' if with_capture else ''}demo"
          + (f": {', '.join(flagged)}" if flagged else ""))


def _pct(frac: float | None) -> str:
    return "-" if frac is None else f"{100 * frac:.0f}%"


def _as_json(rt: Retarget, checks: list[JointCheck], frames: int) -> dict[str, Any]:
    return {
        "frames": frames,
        "joints": [
            {"joint": c.joint, "range_deg": list(c.range_deg),
             "offset_deg": float(rt.offset_deg[k]),
             "sources": {hand.CURVE_NAMES[i]: float(g) for i, g in enumerate(rt.gain[k])
                         if g != 0.0},
             "anatomical_deg": list(c.anatomical_deg),
             "capture_deg": None if c.capture_deg is None else list(c.capture_deg),
             "demo_deg": None if c.demo_deg is None else list(c.demo_deg),
             "demo_low_frac": c.demo_low_frac, "demo_high_frac": c.demo_high_frac,
             "demo_cover_frac": c.demo_cover_frac,
             "flags": list(c.flags)}
            for k, c in enumerate(checks)
        ],
    }
