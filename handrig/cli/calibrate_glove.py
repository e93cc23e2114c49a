"""``handrig calibrate glove``: a guided sequence that measures each glove channel.

Steps: open hand, fist, thumb to little finger, thumb spread. For every step the
glove is read for ``--hold`` seconds (after ``--settle`` seconds to get there)
and the median of each raw channel is kept. Then, per calibrated channel:
``raw_open`` = the open-hand median; ``raw_closed`` = the step median farthest
from it in the channel's closing direction (the direction of the current
``raw_open -> raw_closed``, so reversed sensors stay reversed). The curves and
their open/closed angles are kept from the current config.

Where it reads and writes: it starts from ``--glove-config``, else the glove file
a run with ``--rig`` uses (the rig file's ``[loop] glove``, else your own
glove.toml in $XDG_CONFIG_HOME/handrig, ~/.config/handrig when unset, else the
installed config/glove.toml); the files are printed first. It writes ``--out``;
by default back to the file it started from when that is your own, and to your
own glove.toml when it started from the installed one, which is never rewritten;
``handrig run`` reads your glove.toml without being told. Only the measured
values change: the shipped comments and layout stay. Every write first keeps a
dated copy in ``backups/`` beside the file; ``handrig calibrate undo`` puts it back.

The port given with ``--glove`` is saved in the file, except a pseudo-terminal
(``/dev/pts/N``, an emulator's, gone when it exits); when the adapter also has a
name under ``/dev/serial/by-id/`` (which survives replugging) that name is saved.

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
from tomlkit.toml_document import TOMLDocument

from handrig.app.sources import Source, format_sources, glove_file, rig_file
from handrig.cli._numbers import nonnegative_float, positive_float
from handrig.cli._ports import by_id_for, is_transient
from handrig.cli._rig import add_rig_argument
from handrig.clock import Clock, MonotonicClock
from handrig.config.paths import CONFIG_HOME_HELP, output_for, user_config
from handrig.config.toml_edit import edit, undo, write_with_backup
from handrig.devices.glove import GloveSource, SerialGlove
from handrig.devices.glove_calibration import (
    CALIBRATION_STEPS,
    GloveConfig,
    load_glove_config,
)
from handrig.errors import DataError, DeviceError, HandrigError
from handrig.pose.imu_mount import IMU_STEPS, mount_from_poses, mount_xyzw, up_in_imu
from handrig.pose.robot_rig import load_rig

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
    p.add_argument("--glove-config", default=None, metavar="FILE",
                   help="glove file to start from (default: the rig file's [loop] glove, else "
                        f"glove.toml in {CONFIG_HOME_HELP}, else the installed config/glove.toml)")
    p.add_argument("--config", dest="glove_config", default=None, help=argparse.SUPPRESS)
    add_rig_argument(p, old_name=False)
    p.add_argument("--out", default=None, metavar="FILE",
                   help="where to write (default: the file it starts from if it is yours, "
                        "else glove.toml in the user config directory; the installed file is "
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
    rig_source = rig_file(args.rig)
    rig_cfg = load_rig(rig_source.path)
    source = glove_file(rig_source.path, rig_cfg, args.glove_config)
    src = source.path
    cfg = load_glove_config(src)
    out_path = Path(args.out) if args.out else output_for(src, "glove.toml")
    print(format_sources([rig_source, source, Source(
        "writes to", out_path, "--out" if args.out else
        "default: your own copy, with a dated backup")]), flush=True)
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
    print(f"calibrating the glove on {port} ({fmt}); {len(CALIBRATION_STEPS)} poses", flush=True)
    with glove:
        steps = list(CALIBRATION_STEPS)
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
            if name in dict(CALIBRATION_STEPS):
                medians[name] = np.median(rows, axis=0)
            print(f"      {len(rows)} samples", flush=True)
            if n == len(CALIBRATION_STEPS) and not args.no_imu and any(quats.values()):
                steps += IMU_STEPS
                print(f"the glove sends an IMU orientation: {len(IMU_STEPS)} more poses "
                      "measure how the IMU sits on the forearm", flush=True)
    new_cfg, report = derive(cfg, medians, full_scale)
    if len(steps) > len(CALIBRATION_STEPS):
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
    port_note = ""
    saved_port: str | None = None
    if args.glove:
        if is_transient(port):
            port_note = (f"port {port} not saved: a pseudo-terminal (an emulator's) is gone "
                         "when its program exits; the file keeps "
                         f"port = {cfg.glove.port!r}")
        else:
            stable = by_id_for(port)
            saved_port = str(stable) if stable is not None else port
            if stable is not None:
                port_note = (f"port saved as {stable}: the same adapter as {port}, under a "
                             "name that stays when it is plugged in again")
    text = edit(src.read_text(encoding="utf-8"),
                lambda doc: _write_values(doc, new_cfg, saved_port, fmt), file=str(src))
    out_path.parent.mkdir(parents=True, exist_ok=True)
    backup = write_with_backup(out_path, text)
    try:
        load_glove_config(out_path)  # what was written must load
    except HandrigError:
        undo(out_path)  # put back what was there: a file that does not load helps nobody
        raise
    print(f"wrote {out_path}")
    print(f"  backup of what was there: {backup} (`handrig calibrate undo` puts it back)")
    if port_note:
        print(f"  {port_note}")
    if glove_file(rig_source.path, rig_cfg).path.resolve() == out_path.resolve():
        print("  `handrig run` reads it from now on"
              + ("" if out_path.resolve() == user_config("glove.toml").resolve()
                 else f" (the glove file of {rig_source.path.name})"))
    else:
        print(f"  use it with: handrig run --glove-config {out_path}")
    return 0


def _write_values(doc: TOMLDocument, cfg: GloveConfig, port: str | None, fmt: str) -> None:
    """Set the measured values (and the port, if any) in the glove file's document."""
    for table, ch in zip(doc["channels"], cfg.channels, strict=True):
        table["raw_open"] = ch.raw_open
        table["raw_closed"] = ch.raw_closed
    imu = doc.setdefault("imu", {})
    if list(imu.get("mount_xyzw", [0.0, 0.0, 0.0, 1.0])) != list(cfg.imu.mount_xyzw):
        imu["mount_xyzw"] = list(cfg.imu.mount_xyzw)
    if port is not None:
        glove = doc.setdefault("glove", {})
        glove["port"] = port
        glove["format"] = fmt
