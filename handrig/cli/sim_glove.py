"""``handrig sim-glove``: an emulated glove on a pseudo-terminal.

``handrig sim-glove FILE`` streams a glove recording (CSV, see
handrig/devices/glove_recording.py) in real time. ``handrig sim-glove --calibration``
performs the poses ``handrig calibrate glove`` asks for instead (open hand, fist,
thumb to little finger, thumb spread, with sensor noise; sim/calibration_motion.py),
so the calibration can be rehearsed and tested without a glove:

* on a timer (default): each pose for ``--pose-s`` seconds, in the calibration's
  order, round and round; each pose is announced (``pose 2/4 fist: ...``) when
  the glove starts moving into it: press Enter in ``calibrate glove`` then;
* ``--cue``: the glove holds its pose until a line arrives on standard input:
  an empty line moves to the next pose, a pose name (``fist``) to that pose;
  ``pose NAME held`` is printed once it is there.

``--imu-askew YAW,ROLL`` emulates the forearm IMU fixed askew by those degrees
(turned about the back of the forearm, then rolled about its length): a recording's
orientations are turned accordingly; with ``--calibration`` the glove also performs
the two forearm poses the calibration then asks for, which should find that mount.

The emulated sensors read the ranges of the glove config (``--glove-config``),
narrowed to ``--travel`` of each span, and are printed at the start: a
calibration should find those. The first line is always ``port: /dev/pts/N``;
point ``handrig run --glove`` or ``handrig calibrate glove --glove`` at it.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from handrig.cli._numbers import float_in, nonnegative_float, positive_float, whole_int
from handrig.devices.glove_recording import GloveRecording, read_glove_recording
from handrig.errors import DataError


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "sim-glove",
        help="an emulated glove on a pty: stream a recording, or perform the calibration poses "
             "(prints 'port: PATH' first)",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("file", nargs="?", default=None,
                   help="glove recording (CSV) to stream; omit with --calibration")
    p.add_argument("--format", choices=("frames", "opengloves"), default="frames",
                   help="wire format (default: frames, firmware_protocol/SPEC.md)")
    p.add_argument("--rate", type=positive_float, default=None, metavar="HZ",
                   help="send at this rate (default: the recording's own timestamps; "
                        "200 with --calibration)")
    p.add_argument("--loop", action="store_true", help="start over at the end, until Ctrl-C")
    p.add_argument("--analog-max", type=int, default=4095, choices=(1023, 4095),
                   help="OpenGloves value range (1023 AVR, 4095 ESP32)")
    cal = p.add_argument_group("scripted calibration")
    cal.add_argument("--calibration", action="store_true",
                     help="perform the poses of `handrig calibrate glove` instead of a file")
    cal.add_argument("--cue", action="store_true",
                     help="change pose on a line of standard input, not on a timer")
    cal.add_argument("--pose-s", type=positive_float, default=None, metavar="S",
                     help="seconds per pose on the timer (default: calibrate glove's "
                          "settle + hold + 2 s to press Enter: 5)")
    cal.add_argument("--transition-s", type=nonnegative_float, default=0.5, metavar="S",
                     help="seconds to move into a pose (default 0.5; keep it below "
                          "calibrate glove's --settle)")
    cal.add_argument("--noise", type=nonnegative_float, default=6.0, metavar="COUNTS",
                     help="sensor noise, standard deviation in raw counts (default 6)")
    cal.add_argument("--travel", type=float_in(0.0, 1.0), default=0.85, metavar="FRACTION",
                     help="the emulated sensors' travel as a fraction of the spans in the "
                          "glove config (default 0.85)")
    cal.add_argument("--glove-config", default=None, metavar="FILE",
                     help="glove config whose channels are emulated (default: the one "
                          "`handrig calibrate glove` starts from)")
    cal.add_argument("--seed", type=whole_int, default=0, help="noise seed (default 0)")
    cal.add_argument("--imu-askew", type=_yaw_roll, default=None, metavar="YAW,ROLL",
                     help="emulate the forearm IMU mounted askew by YAW and ROLL degrees "
                          "(frames only), e.g. 30,15; also for a recording FILE")
    p.set_defaults(func=run)


def _yaw_roll(text: str) -> tuple[float, float]:
    try:
        yaw, roll = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give YAW,ROLL in degrees, e.g. 30,15"
                                         ) from None
    if not (abs(yaw) <= 180 and abs(roll) <= 180):
        raise argparse.ArgumentTypeError(f"{text!r}: each angle within -180..180 degrees")
    return yaw, roll


def run(args: argparse.Namespace) -> int:
    if args.rate is not None and not 1.0 <= args.rate <= 5000.0:
        raise DataError(f"--rate {args.rate} out of range: use 1..5000 Hz")
    if args.calibration:
        if args.file:
            raise DataError("give a recording FILE or --calibration, not both")
        return _run_calibration(args)
    if args.cue:
        raise DataError("--cue is for --calibration: add --calibration")
    if not args.file:
        raise DataError("no recording: give FILE.csv, or --calibration for the scripted poses")
    return _run_file(args)


def _run_file(args: argparse.Namespace) -> int:
    from handrig.app import simulator
    rec = read_glove_recording(args.file)
    if args.imu_askew:
        rec = _askew(rec, args)
    with simulator.glove_emulator(rec, args.format, rate_hz=args.rate, loop=args.loop,
                                  analog_max=args.analog_max) as emu:
        print(f"port: {emu.port_path}", flush=True)
        rate = args.rate or rec.nominal_rate_hz
        print(f"streaming {len(rec)} samples ({rec.duration_s:.1f} s) as {args.format} at "
              f"{rate:.0f} Hz{' in a loop' if args.loop else ''}; Ctrl-C stops", flush=True)
        try:
            while not emu.done.wait(0.2):
                pass
        except KeyboardInterrupt:
            pass
        sent, dropped = emu.frames_sent, emu.bytes_dropped
    _say_sent(sent, dropped)
    return 0


def _askew(rec: GloveRecording, args: argparse.Namespace) -> GloveRecording:
    """The recording as an IMU mounted askew by ``--imu-askew`` would have sent it."""
    import dataclasses

    import numpy as np
    from scipy.spatial.transform import Rotation

    from handrig.pose.imu_mount import askew_mount, imu_quaternion

    if args.format != "frames" or rec.quat_xyzw is None:
        raise DataError("--imu-askew needs --format frames and a recording with an IMU "
                        "(qx,qy,qz,qw columns)")
    q = rec.quat_xyzw
    ok = ~np.isnan(q).any(axis=1)
    out = q.copy()
    out[ok] = imu_quaternion(Rotation.from_quat(q[ok]), askew_mount(*args.imu_askew))
    return dataclasses.replace(rec, quat_xyzw=out)


def _say_sent(sent: int, dropped: int) -> None:
    print(f"sent {sent} frames" + (f", {dropped} bytes dropped (nobody reading)"
                                   if dropped else ""), flush=True)


def _run_calibration(args: argparse.Namespace) -> int:
    from handrig.app import simulator
    from handrig.cli.calibrate_glove import DEFAULT_HOLD_S, DEFAULT_SETTLE_S
    from handrig.config.paths import config_file
    from handrig.devices.glove_calibration import CALIBRATION_STEPS, load_glove_config
    from handrig.pose.imu_mount import IMU_STEPS, askew_mount

    motion = simulator.calibration_motion()
    ScriptedSensors = motion.ScriptedSensors
    move_recording, timed_recording = motion.move_recording, motion.timed_recording
    if args.imu_askew and args.format != "frames":
        raise DataError("--imu-askew needs --format frames (OpenGloves lines carry no IMU)")
    mount = askew_mount(*args.imu_askew) if args.imu_askew else None
    POSE_NAMES = motion.pose_names(mount is not None)

    cfg = load_glove_config(args.glove_config or config_file("glove.toml"))
    rate = args.rate or 200.0
    full_scale = float(args.analog_max if args.format == "opengloves" else 4095)
    n_raw = 5 if args.format == "opengloves" else 0
    sensors = ScriptedSensors.from_config(cfg, n_raw=n_raw, travel=args.travel,
                                          full_scale=full_scale)
    texts = dict(CALIBRATION_STEPS + IMU_STEPS)
    pose_s = args.pose_s if args.pose_s is not None else DEFAULT_SETTLE_S + DEFAULT_HOLD_S + 2
    common: dict[str, Any] = {"transition_s": args.transition_s, "rate_hz": rate,
                              "noise_counts": args.noise, "imu_mount": mount}
    if args.cue:
        first = move_recording(sensors, POSE_NAMES[0], POSE_NAMES[0], seed=args.seed, **common)
        emu = simulator.glove_emulator(first, args.format, rate_hz=rate, loop=True,
                                       loop_from_s=args.transition_s,
                                       analog_max=args.analog_max)
    else:
        rec = timed_recording(sensors, pose_s=pose_s, seed=args.seed, **common)
        emu = simulator.glove_emulator(rec, args.format, rate_hz=rate, loop=True,
                                       analog_max=args.analog_max)
    with emu:
        print(f"port: {emu.port_path}", flush=True)
        print(f"scripted calibration as {args.format} at {rate:g} Hz, sensor noise "
              f"{args.noise:g} counts; the emulated sensors (raw counts):", flush=True)
        print("\n".join(sensors.describe()), flush=True)
        if args.imu_askew:
            print(f"forearm IMU mounted askew: yaw {args.imu_askew[0]:g} deg, roll "
                  f"{args.imu_askew[1]:g} deg", flush=True)
        try:
            if args.cue:
                _follow_cues(emu, sensors, texts, args, common, POSE_NAMES)
            else:
                print(f"poses on a timer, {pose_s:g} s each, round and round; Ctrl-C stops",
                      flush=True)
                _announce_timed(emu, POSE_NAMES, texts, pose_s)
        except KeyboardInterrupt:
            pass
        sent, dropped = emu.frames_sent, emu.bytes_dropped
    _say_sent(sent, dropped)
    return 0


def _announce_timed(emu: Any, names: tuple[str, ...], texts: dict[str, str],
                    pose_s: float) -> None:
    """Print each pose as the glove starts moving into it (the timer runs on its own)."""
    start = emu.clock.now()
    n = 0
    while True:
        emu.clock.sleep_until(start + n * pose_s)
        name = names[n % len(names)]
        print(f"pose {n % len(names) + 1}/{len(names)} {name}: {texts[name]}", flush=True)
        n += 1


def _follow_cues(emu: Any, sensors: Any, texts: dict[str, str], args: argparse.Namespace,
                 common: dict[str, Any], names: tuple[str, ...]) -> None:
    from handrig.app import simulator
    move_recording = simulator.calibration_motion().move_recording
    current = names[0]
    print(f"pose {current} held; Enter moves to the next pose, a name "
          f"({', '.join(names)}) to that one", flush=True)
    seed = args.seed
    for line in sys.stdin:
        word = line.strip()
        if word in ("q", "quit"):
            return
        if word == "":
            target = names[(names.index(current) + 1) % len(names)]
        elif word in names:
            target = word
        else:
            print(f"not a pose: {word!r}; one of {', '.join(names)}, or Enter",
                  flush=True)
            continue
        seed += 1
        emu.play(move_recording(sensors, current, target, seed=seed, **common), loop=True,
                 loop_from_s=args.transition_s)
        print(f"pose {target}: {texts[target]}", flush=True)
        emu.clock.sleep(args.transition_s)
        print(f"pose {target} held", flush=True)
        current = target
