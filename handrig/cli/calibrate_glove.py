"""``handrig calibrate glove``: a guided sequence that measures each glove channel.

Steps: open hand, fist, thumb to little finger, thumb spread. For every step the
glove is read for ``--hold`` seconds (after ``--settle`` seconds to get there)
and the median of each raw channel is kept. Then, per calibrated channel:
``raw_open`` = the open-hand median; ``raw_closed`` = the step median farthest
from it in the channel's closing direction (the direction of the current
``raw_open -> raw_closed``, so reversed sensors stay reversed). The curves and
their open/closed angles are kept from the current config.

Where it reads and writes: it starts from ``--config``, by default your own
glove.toml ($XDG_CONFIG_HOME/handrig/glove.toml, ~/.config/handrig when unset)
if there is one, else the installed config/glove.toml. It writes ``--out``; by
default back to ``--config`` when that is your own file, and to your own
glove.toml when it started from the installed one, which is never rewritten.
Use the result with ``handrig run --glove-config FILE``.

Interactive by default (Enter starts each step); ``--yes`` runs the steps on a
timer with no input, for scripts and tests. ``handrig sim-glove --calibration``
is an emulated glove that performs the poses, to rehearse without a glove.

When the glove sends an IMU orientation (handrig frames), two more poses follow
(forearm level palm down; palm vertical, thumb up) and the IMU's mounting on the
forearm is measured from them and written as ``[imu] mount_xyzw``
(:mod:`handrig.pose.imu_mount`); ``--no-imu`` skips them.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from handrig.cli._numbers import nonnegative_float, positive_float
from handrig.clock import Clock, MonotonicClock
from handrig.config.paths import CONFIG_HOME_HELP, config_file, output_for
from handrig.devices.glove import GloveSource, SerialGlove
from handrig.devices.glove_calibration import (
    GloveConfig,
    glove_config_to_toml,
    load_glove_config,
)
from handrig.errors import DataError, DeviceError
from handrig.pose.imu_mount import IMU_STEPS, mount_from_poses, mount_xyzw, up_in_imu

STEPS: tuple[tuple[str, str], ...] = (
    ("open", "Open hand: fingers straight and together, thumb relaxed beside the index."),
    ("fist", "Fist: close every finger, thumb wrapped over the middle finger."),
    ("thumb-oppose", "Thumb to little finger: touch the two tips together."),
    ("thumb-spread", "Thumb spread: move the thumb as far from the index as is comfortable."),
)
DEFAULT_SETTLE_S = 1.0
DEFAULT_HOLD_S = 2.0
MIN_SPAN_FRACTION = 0.02
"""A channel must move at least this fraction of its full scale between open and closed."""


def calibrate_subparsers(sub: Any) -> Any:
    """The ``handrig calibrate`` parser's subcommand set, created on first use.

    ``calibrate glove`` (this module) and ``calibrate servos`` share one
    ``calibrate`` parser; whichever module registers first creates it.
    """
    parser = sub.choices.get("calibrate")
    if parser is None:
        parser = sub.add_parser(
            "calibrate", help="calibrate the glove or the servos and write the config files",
            description="Guided calibration; each subcommand writes its config file.",
        )
        parser.set_defaults(func=lambda _args: _usage(parser))
        return parser.add_subparsers(dest="calibrate_what", metavar="WHAT")
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action
    return parser.add_subparsers(dest="calibrate_what", metavar="WHAT")


def _usage(parser: argparse.ArgumentParser) -> int:
    parser.print_help()
    return 2


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = calibrate_subparsers(sub).add_parser(
        "glove", help="guided glove calibration (open hand, fist, thumb poses) -> glove.toml",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--config", default=None, metavar="FILE",
                   help=f"glove config to start from (default: glove.toml in {CONFIG_HOME_HELP}"
                        ", else the installed config/glove.toml)")
    p.add_argument("--out", default=None, metavar="FILE",
                   help="where to write (default: the --config file if it is yours, else "
                        "glove.toml in the user config directory; the installed file is "
                        "never rewritten)")
    p.add_argument("--glove", default=None, metavar="PORT",
                   help="glove port, or opengloves:PORT (default: [glove] port of the config)")
    p.add_argument("--hold", type=positive_float, default=DEFAULT_HOLD_S, metavar="S",
                   help=f"seconds to record each pose (default {DEFAULT_HOLD_S:g})")
    p.add_argument("--settle", type=nonnegative_float, default=DEFAULT_SETTLE_S, metavar="S",
                   help=f"seconds to get into each pose before recording "
                        f"(default {DEFAULT_SETTLE_S:g})")
    p.add_argument("--no-imu", action="store_true",
                   help="skip the two forearm poses that measure the IMU's mounting")
    p.add_argument("--yes", action="store_true",
                   help="no questions: run the steps on the timer and write the file")
    p.set_defaults(func=run)


def _port_and_format(args: argparse.Namespace, cfg: GloveConfig) -> tuple[str, str]:
    spec = args.glove or cfg.glove.port
    if not spec:
        raise DeviceError("no glove port: pass --glove PORT (or opengloves:PORT), or set "
                          "[glove] port in the glove config")
    if spec.startswith("opengloves:"):
        return spec.removeprefix("opengloves:"), "opengloves"
    if spec.startswith("frames:"):
        return spec.removeprefix("frames:"), "frames"
    return spec, cfg.glove.format


def record_step(glove: GloveSource, clock: Clock, settle_s: float, hold_s: float,
                port: str, quats: list[np.ndarray] | None = None) -> np.ndarray:
    """Raw samples (m, n_raw) received during ``hold_s`` after ``settle_s``; the IMU
    quaternions of those samples that have one are appended to ``quats`` if given."""
    t_start = clock.now()
    t_rec = t_start + settle_s
    t_end = t_rec + hold_s
    rows: list[np.ndarray] = []
    while True:
        now = clock.now()
        s = glove.latest()
        if s is not None and s.host_time_s >= t_rec:
            rows.append(s.raw.copy())
            if quats is not None and s.quat is not None:
                quats.append(s.quat.copy())
        if now >= t_end:
            break
        glove.check()
        clock.sleep(0.002)
    if not rows:
        st = glove.stats()
        raise DeviceError(
            f"no glove frames on {port} for {hold_s:g} s (good {st.frames_ok}, errors "
            f"{st.errors}, bytes {st.bytes_read}): is the glove streaming, in this format?"
        )
    return np.array(rows)


def derive(cfg: GloveConfig, medians: dict[str, np.ndarray],
           full_scale: float) -> tuple[GloveConfig, list[str]]:
    """New config from the step medians; raises DataError when a channel did not move."""
    open_raw = medians["open"]
    report = []
    new_channels = []
    for i, ch in enumerate(cfg.channels):
        k = ch.raw_index()
        if k >= open_raw.shape[0]:
            raise DataError(f"channels[{i}] ({ch.curve}) reads raw channel {k} but the glove "
                            f"sends {open_raw.shape[0]}")
        direction = np.sign(ch.raw_closed - ch.raw_open)
        o = float(open_raw[k])
        candidates = [float(m[k]) for name, m in medians.items() if name != "open"]
        c = max(candidates, key=lambda v: direction * (v - o))
        span = abs(c - o)
        if direction * (c - o) < MIN_SPAN_FRACTION * full_scale:
            raise DataError(
                f"channels[{i}] ({ch.curve}, raw channel {k}) barely moved: open {o:.0f}, "
                f"best closed {c:.0f} (needs {MIN_SPAN_FRACTION * full_scale:.0f} counts "
                "in its closing direction); check the sensor and run the calibration again"
            )
        lo = min(float(m[k]) for m in medians.values())
        hi = max(float(m[k]) for m in medians.values())
        report.append(f"  {k:>3}  {ch.curve:<14} open {o:7.0f}  closed {c:7.0f}  "
                      f"span {span:6.0f}  (min {lo:.0f}, max {hi:.0f})")
        new_channels.append(dataclasses.replace(ch, raw_open=round(o, 1),
                                                raw_closed=round(c, 1)))
    return dataclasses.replace(cfg, channels=tuple(new_channels)), report


def run(args: argparse.Namespace) -> int:
    src = Path(args.config) if args.config else config_file("glove.toml")
    cfg = load_glove_config(src)
    out_path = Path(args.out) if args.out else output_for(src, "glove.toml")
    port, fmt = _port_and_format(args, cfg)
    if args.hold <= 0 or args.settle < 0:
        raise DataError("--hold must be positive and --settle zero or positive")
    clock = MonotonicClock()
    full_scale = float(cfg.glove.analog_max if fmt == "opengloves" else 4095)
    glove = SerialGlove(port, fmt, clock=clock, baud=cfg.glove.baud,  # type: ignore[arg-type]
                        analog_max=cfg.glove.analog_max, estop_letter=cfg.glove.estop_letter,
                        reconnect_s=0)
    medians: dict[str, np.ndarray] = {}
    quats: dict[str, list[np.ndarray]] = {}
    print(f"calibrating the glove on {port} ({fmt}); {len(STEPS)} poses", flush=True)
    with glove:
        steps = list(STEPS)
        n = 0
        while n < len(steps):
            name, text = steps[n]
            n += 1
            print(f"[{n}/{len(steps)}] {text}", flush=True)
            if not args.yes:
                input("      press Enter when ready, then hold still ")
            print(f"      recording {args.hold:g} s ...", flush=True)
            quats[name] = []
            rows = record_step(glove, clock, args.settle, args.hold, port, quats[name])
            if name in dict(STEPS):
                medians[name] = np.median(rows, axis=0)
            print(f"      {len(rows)} samples", flush=True)
            if n == len(STEPS) and not args.no_imu and any(quats.values()):
                steps += IMU_STEPS
                print(f"the glove sends an IMU orientation: {len(IMU_STEPS)} more poses "
                      "measure how the IMU sits on the forearm", flush=True)
    new_cfg, report = derive(cfg, medians, full_scale)
    if len(steps) > len(STEPS):
        mount = mount_from_poses(*(up_in_imu(np.array(quats[name])) for name, _ in IMU_STEPS))
        new_cfg = dataclasses.replace(
            new_cfg, imu=dataclasses.replace(new_cfg.imu, mount_xyzw=mount_xyzw(mount)))
        yaw, _pitch, roll = mount.inv().as_euler("ZYX", degrees=True)
        report.append(f"  IMU mount_xyzw {list(mount_xyzw(mount))}: the IMU sits turned "
                      f"{yaw:.1f} deg about the forearm's back and rolled {roll:.1f} deg "
                      f"about its length ({mount.magnitude() * 180 / np.pi:.1f} deg in all)")
    print("channel curve           readings (raw counts)")
    print("\n".join(report))
    if not args.yes:
        answer = input(f"write {out_path}? [Y/n] ").strip().lower()
        if answer not in ("", "y", "yes"):
            print("not written", file=sys.stderr)
            return 1
    if args.glove:
        new_cfg = dataclasses.replace(
            new_cfg, glove=dataclasses.replace(new_cfg.glove, port=port, format=fmt))  # type: ignore[arg-type]
    header = ("# handrig glove: written by `handrig calibrate glove`.\n"
              "# Format: handrig/glove_calibration.py.\n")
    out_path.parent.mkdir(parents=True, exist_ok=True)
    out_path.write_text(header + tomli_w.dumps(glove_config_to_toml(new_cfg)), encoding="utf-8")
    load_glove_config(out_path)  # what was written must load
    print(f"wrote {out_path}")
    print(f"  use it with: handrig run --glove-config {out_path}")
    return 0
