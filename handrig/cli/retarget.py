"""``handrig retarget check`` and ``fit``: a robot hand's retarget table.

``check`` prints the table (each robot joint's source curves with their gains, the
offset and the robot's range), then for each joint the range its sources reach: over
the human joint limits, over the shipped reference capture, and over the demo glove
recording expanded through the map, as the demo feeds it. Joints whose inputs
reach past the robot's range are flagged, and the share of demo frames clipped at
each robot limit is given. Then, through the robot's MJCF model (MuJoCo): the fist
closure per finger (the share of its flexion range reached at the human fist; target
>= 0.9), the thumb-finger tip gaps at the human's pinches (target <= 10 mm) and the
fingertip error over the reference capture (median, p95, mm, the human's carried
onto the robot and scaled to it). Exit status 1 when a joint is flagged (the capture
or the demo reaches past its range: the robot sits at a limit there), 0 when none is.

``fit`` fits the table's gains and offsets through the robot's model so that its
fingertips follow the human's (positions relative to the palm, pinches, the fist;
see sim/retarget_fit.py) and writes the table (the rig's own unless --out); the
realtime step stays the same linear map.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from handrig import hand
from handrig.cli._numbers import positive_int
from handrig.config.loading import CONFIG_DIR, load_joint_limits
from handrig.errors import ConfigError
from handrig.pose.retarget import JointCheck, Retarget, check_joints, load_retarget

if TYPE_CHECKING:
    from handrig.pose.robot_rig import RobotRigConfig

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
    c.add_argument("--no-model", action="store_true",
                   help="skip the figures through the robot's model (fist, pinch, tips)")
    c.add_argument("--render", default=None, metavar="FILE.png",
                   help="draw the robot at the human's open hand, fist and pinches "
                   "(MUJOCO_GL=egl offscreen)")
    c.add_argument("--view", default=None, metavar="D,AZ,EL",
                   help="--render's camera: distance m, azimuth and elevation deg "
                   "(default: the rig's render_view)")
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(func=run_check)
    f: argparse.ArgumentParser = actions.add_parser(
        "fit", help="fit the table through the robot's model (fingertips, pinches, fist) "
        "and write it", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    f.add_argument("--rig", default=DEFAULT_RIG,
                   help=f"robot rig preset or file (default {DEFAULT_RIG!r})")
    f.add_argument("--out", default=None, metavar="FILE.toml",
                   help="where to write the table (default: the rig's own table)")
    f.add_argument("--dry-run", action="store_true",
                   help="fit and print the figures, write nothing")
    f.add_argument("--hold", default="", metavar="JOINT,...",
                   help="robot joints to keep as the table has them (all the thumb's: "
                   "no pinch terms)")
    f.add_argument("--couple", action="store_true",
                   help="let the thumb joints also read the index and middle fingers' "
                   "flexion (the thumb closes toward a closing finger)")
    f.add_argument("--max-evaluations", type=positive_int, default=60, metavar="N",
                   help="solver evaluations per stage (default 60)")
    f.add_argument("--json", action="store_true", help="print one JSON object")
    f.set_defaults(func=run_fit)

    def usage(args: argparse.Namespace) -> int:
        p.print_help()
        return 2

    p.set_defaults(func=usage)


def _robot_rig(name: str) -> RobotRigConfig:
    from handrig.config.rig_files import rig_file_path
    from handrig.pose.robot_rig import RobotRigConfig, load_rig

    rig = load_rig(name)
    if not isinstance(rig, RobotRigConfig) or rig.robot is None:
        raise ConfigError("not a robot rig: it has no [robot] table with a retarget table",
                          file=str(rig_file_path(name)),
                          allowed="a robot rig such as 'leap', or --table FILE")
    return rig


def _rig_parts(args: argparse.Namespace) -> tuple[Retarget, Path, str, str, str]:
    """The retarget table, the rig's folder, its map and glove settings, its model
    (empty with --table)."""
    from handrig.config.rig_files import rig_file_path
    from handrig.pose.robot_rig import robot_retarget

    if args.table is not None:
        return load_retarget(args.table), Path(args.table).resolve().parent, "", "", ""
    rig = _robot_rig(args.rig)
    assert rig.robot is not None  # _robot_rig checked it
    base = rig_file_path(args.rig).resolve().parent
    return robot_retarget(rig), base, rig.loop.map, rig.loop.glove, rig.robot.model


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
    rt, base, map_path, glove_path, model = _rig_parts(args)
    limits = load_joint_limits()
    bounds = np.array([limits.of(n) for n in hand.CURVE_NAMES], dtype=np.float64)
    capture = None
    if not args.no_capture:
        from handrig.offline.mocap import load_reference

        capture = load_reference().curves
    demo = _demo_poses(args.recording, base, map_path, glove_path)
    checks = check_joints(rt, bounds[:, 0], bounds[:, 1], capture, demo)
    flagged = any(set(c.flags) & {"capture", "demo"} for c in checks)
    grasp: dict[str, Any] | None = None
    if args.render and not model:
        raise ConfigError("--render draws the rig's robot model: give --rig, not --table",
                          key="--render", value=args.render)
    if model and (not args.no_model or args.render):
        from handrig.app.simulator import retarget_fitter

        gm = retarget_fitter().GraspModel(rt, model, capture)
        if not args.no_model:
            grasp = gm.grade(rt).as_json()
        if args.render:
            _render_grasps(rt, gm, model, args)
    if args.json:
        print(json.dumps(_as_json(rt, checks, len(demo)) | (grasp or {})))
        return 1 if flagged else 0
    _print_table(rt)
    print()
    _print_checks(checks, len(demo), capture is not None)
    if grasp is not None:
        print()
        _print_grasp(grasp)
    return 1 if flagged else 0


def _render_grasps(rt: Retarget, gm: Any, model: str, args: argparse.Namespace) -> None:
    """The robot at the human's open hand, fist and middle pinches, one tile each."""
    from handrig.app.simulator import render_strip
    from handrig.pose.robot_rig import load_rig, render_view

    poses = [np.zeros(len(hand.CURVE_NAMES)), gm.fist]
    labels = ["human open hand", "human fist"]
    for finger in ("Index", "Middle"):
        mine = [p for p in gm.pinches if p.finger == finger]
        if mine:
            poses.append(mine[len(mine) // 2].pose_deg)
            labels.append(f"human thumb-{finger.lower()} pinch")
    frames = list(rt.apply_many(np.array(poses)))
    view = render_view(load_rig(args.rig))
    if args.view:
        try:
            d, az, el = (float(v) for v in args.view.split(","))
        except ValueError:
            raise ConfigError("not a camera view", key="--view", value=args.view,
                              allowed="distance,azimuth,elevation, e.g. 0.3,0,-20") from None
        view = (d, az, el)
    out = render_strip(frames, rt.joint_names, args.render, model=model, view=view,
                       labels=labels)
    print(f"wrote {out}", file=sys.stderr)


def _print_grasp(g: dict[str, Any], before: dict[str, Any] | None = None) -> None:
    def was(path: tuple[str, str], fmt: str) -> str:
        if before is None:
            return ""
        return f" (was {format(before[path[0]][path[1]], fmt)})"

    print("through the robot's model (MuJoCo): the human fist, pinches and capture")
    for finger, c in g["fist_closure"].items():
        mark = "ok" if c >= FIST_TARGET else f"below {FIST_TARGET:g}"
        print(f"  fist closure {finger:<7} {c:5.2f}{was(('fist_closure', finger), '.2f')}  "
              f"{mark}")
    for pair, gap in g["pinch_gap_mm"].items():
        mark = "ok" if gap <= PINCH_TARGET_MM else f"above {PINCH_TARGET_MM:g} mm"
        print(f"  pinch gap {pair:<13} {gap:6.1f} mm{was(('pinch_gap_mm', pair), '.1f')}  "
              f"{mark}")
    e = g["tip_error_mm"]
    if not e:
        print("  fingertip error over the capture: - (no capture: --no-capture)")
        return
    print(f"  fingertip error over the capture: median {e['median']:.1f} mm"
          f"{was(('tip_error_mm', 'median'), '.1f')}, p95 {e['p95']:.1f} mm"
          f"{was(('tip_error_mm', 'p95'), '.1f')}; by digit (median): "
          + ", ".join(f"{k[:-7]} {v:.1f}" for k, v in e.items() if k.endswith("_median")))


def run_fit(args: argparse.Namespace) -> int:
    from handrig.app.simulator import retarget_fitter
    from handrig.offline.mocap import load_reference
    from handrig.pose.retarget import table_text
    from handrig.pose.robot_rig import robot_retarget

    rig = _robot_rig(args.rig)
    assert rig.robot is not None  # _robot_rig checked it
    out = Path(args.out) if args.out else Path(rig.robot.retarget)
    rt = robot_retarget(rig)
    fitter = retarget_fitter()
    say = (lambda msg: None) if args.json else print
    hold = [j for j in args.hold.split(",") if j]
    for j in hold:
        if j not in rt.joint_names:
            raise ConfigError("no such joint in the retarget table", key="--hold", value=j,
                              allowed=", ".join(rt.joint_names))
    result = fitter.fit_retarget(rt, rig.robot.model, load_reference().curves,
                                 progress=say, max_evaluations=args.max_evaluations,
                                 hold=hold, couple=args.couple)
    if not args.dry_run:
        flags = (" --hold " + ",".join(hold) if hold else "") + (
            " --couple" if args.couple else "")
        header = FIT_HEADER.format(rig=args.rig, name=rig.robot.name or args.rig,
                                   model=Path(rig.robot.model).name, hold=flags)
        if args.couple:
            header += COUPLE_NOTE
        if hold:
            header += HOLD_NOTE.format(joints=", ".join(hold))
        out.write_text(table_text(result.retarget, header))
        load_retarget(out)  # what was written loads back
    if args.json:
        print(json.dumps({"before": result.before.as_json(), "after": result.after.as_json(),
                          "evaluations": result.iterations, "solver": result.message,
                          "written": None if args.dry_run else str(out)}))
        return 0
    print(f"solver: {result.message} ({result.iterations} evaluations)")
    _print_grasp(result.after.as_json(), result.before.as_json())
    print("nothing written (--dry-run)" if args.dry_run else f"wrote {out}")
    return 0


HOLD_NOTE = """
Held as they were (not fitted): {joints}.
"""
COUPLE_NOTE = """
The thumb's flexion joints also read the index and middle fingers' MCP and PIP
flexion (--couple; either sign): the thumb closes toward a finger as the finger
closes, which is how the linear table meets the pinches. Its base (abduction, twist)
reads only its own curves, at least 0.7 deg per deg.
"""
FIST_TARGET = 0.9
PINCH_TARGET_MM = 10.0
FIT_HEADER = """\
handrig retarget table: the 50 human curves -> the joints of the {name}.
  robot_deg = offset_deg + sum over sources of gain * curve_deg, clipped to range_deg
Human curves: vocabulary convention (degrees, flexion positive, abduction positive
toward the thumb). Robot joints: the MJCF joint angle of {model} in degrees.

Fitted by `handrig retarget fit --rig {rig}{hold}` through the robot's model (MuJoCo
kinematics, sim/retarget_fit.py): the robot's fingertips follow the human hand
model's over the reference capture (each tip relative to its digit's base on the
palm, scaled by the digits' lengths), the thumb tip meets the index and middle tips
at the hand model's pinches, each finger closes to 0.95 of its flexion range at the
human fist, and the degrees a joint asks past its range over the capture count
against the fit. Each joint keeps its sources and the signs of their gains.
`handrig retarget check --rig {rig}` prints the figures; re-run the fit after changing
the model or the ranges.
"""


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
