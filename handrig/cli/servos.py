"""``handrig servos``: bring servos up: find them, give them IDs and a baud, reboot one,
and check the bus against the rig file.

New X-series servos all answer as ID 1 at 57600 bps. The usual bring-up: connect
one servo, ``scan``, ``set-id 1 7`` (for the servo that drives servo 7's joint in
the rig file), ``set-baud --baud 57600 7 1000000``, then the next servo; with all
of them chained, ``check`` says whether the bus matches the rig file.
docs/hardware.md covers the adapter, power and wiring.

The port is ``--port``, by default the rig file's ``[bus] port``; ``--port sim``
starts the emulated bus (``handrig sim-bus``) with the rig's servos.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from handrig.app.factory import port_process, servo_bringup
from handrig.app.sources import format_sources, rig_file
from handrig.cli._numbers import whole_int
from handrig.cli._ports import by_id_for, say_if_simulated
from handrig.cli._rig import add_rig_argument
from handrig.config.rig import RigConfig, require_port
from handrig.devices.servo.bringup import BusBringup, FoundServo
from handrig.errors import ConfigError
from handrig.pose.robot_rig import load_rig


def _baud(text: str) -> int:
    kind = servo_bringup()
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value not in kind.bauds:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a baud {kind.family} supports "
            f"({', '.join(map(str, kind.bauds))})")
    return value


def _bauds(text: str) -> list[int]:
    return [_baud(part.strip()) for part in text.split(",") if part.strip()]


def register(sub: Any) -> None:
    bauds = servo_bringup().bauds
    p: argparse.ArgumentParser = sub.add_parser(
        "servos", help="servo bring-up: scan, set-id, set-baud, reboot, check",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.set_defaults(func=lambda _args: _usage(p))
    group = p.add_subparsers(dest="servos_what", metavar="WHAT")

    def common(q: argparse.ArgumentParser, *, baud: bool = True) -> None:
        q.set_defaults(json=False)
        add_rig_argument(q)
        q.add_argument("--port", default=None, metavar="PORT",
                       help="serial port, or 'sim' for the emulated bus (default: the rig "
                       "file's [bus] port)")
        if baud:
            q.add_argument("--baud", type=_baud, default=None, metavar="BPS",
                           help="the baud the servo answers at now (default: the rig file's "
                           "[bus] baud; set-id and set-baud look at every baud, the rig's "
                           "and the factory's 57600 first)")

    s = group.add_parser("scan", help="find servos at every baud; list model, firmware, "
                         "mode, voltage, temperature and errors",
                         description="Broadcast-ping the port at every baud the X series "
                         "supports (or --bauds) and list each servo that answers: ID, "
                         "model, firmware, baud, operating mode, input voltage, temperature "
                         "and hardware errors. A full scan takes about 10 s (9600 bps is slow).")
    common(s, baud=False)
    s.add_argument("--bauds", type=_bauds, default=list(bauds), metavar="LIST",
                   help=f"only these bauds (default all: {','.join(map(str, bauds))})")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=run_scan)

    i = group.add_parser("set-id", help="give a servo another ID (refused if it is taken)",
                         description="Write a servo's ID (EEPROM: torque goes off first). "
                         "Refused when another servo answers as the new ID at this baud. New "
                         "servos all come as ID 1: connect one at a time.")
    common(i)
    i.add_argument("old_id", type=whole_int, help="the ID it answers to now")
    i.add_argument("new_id", type=whole_int, help="the ID to give it (0..252)")
    i.set_defaults(func=run_set_id)

    b = group.add_parser("set-baud", help="move a servo to another baud (refused if its "
                         "ID is taken there)",
                         description="Write a servo's Baud Rate (EEPROM: torque goes off "
                         "first). Refused when another servo with the same ID answers at "
                         "the new baud.")
    common(b)
    b.add_argument("id", type=whole_int, help="the servo's ID")
    b.add_argument("new_baud", type=_baud, help="the baud to move it to, e.g. 1000000")
    b.set_defaults(func=run_set_baud)

    r = group.add_parser("reboot", help="reboot a servo (clears a hardware error whose "
                         "cause is gone)")
    common(r)
    r.add_argument("id", type=whole_int, help="the servo's ID")
    r.set_defaults(func=run_reboot)

    c = group.add_parser("check", help="compare the bus with the rig file: missing, extra, "
                         "wrong model, wrong mode, voltage, errors",
                         description="Ping every servo at the rig's baud and compare with "
                         "its [[servos]] and [servo_settings]: missing and extra servos, "
                         "wrong model, wrong operating mode, input voltage outside the "
                         "model's range, hardware errors; each with what to do. Exit 1 when "
                         "anything differs.")
    common(c)
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(func=run_check)


def _usage(parser: argparse.ArgumentParser) -> int:
    parser.print_help()
    return 2


@contextlib.contextmanager
def _port(args: argparse.Namespace, rig: RigConfig, rig_path: Path) -> Iterator[str]:
    port = require_port(args.port or rig.bus.port, rig_path)
    if say_if_simulated(port, out=not args.json):
        with port_process(["sim-bus", "--rig", str(rig_path), "--no-puppet"],
                          "the simulated servo bus") as (_, pty):
            yield pty
        if not args.json:
            print("SIMULATED: that was the emulated bus (--port sim); no servo of yours "
                  "was touched", flush=True)
        return
    if not os.path.exists(port):
        raise ConfigError(f"no such port: {port}", key="--port", value=port,
                          allowed="the adapter's device, e.g. /dev/ttyUSB0 or a "
                          "/dev/serial/by-id/ name (docs/hardware.md)")
    stable = by_id_for(port)
    if stable is not None:
        print(f"note: {port} is also {stable}; that name stays the same when the adapter "
              "is plugged in again: use it in [bus] port", flush=True)
    yield port


def _rig(args: argparse.Namespace) -> tuple[RigConfig, Path]:
    source = rig_file(args.rig)
    return load_rig(source.path), source.path


def _servos(port: str) -> BusBringup:
    """Bring-up on ``port`` (the factory's, for the servos' vendor)."""
    return servo_bringup()(port)


def _row(s: FoundServo) -> str:
    volts = "?" if s.voltage_v is None else f"{s.voltage_v:.1f} V"
    temp = "?" if s.temperature_c is None else f"{s.temperature_c} C"
    return (f"{s.id:>4}  {s.model:<11} {s.firmware:>3}  {s.baud:>8}  {s.mode_name:<22} "
            f"{volts:>7}  {temp:>5}  {s.errors_text}")


HEADER = f"{'ID':>4}  {'model':<11} {'fw':>3}  {'baud':>8}  {'mode':<22} {'voltage':>7}  " \
         f"{'temp':>5}  hardware errors"


def _as_dict(s: FoundServo) -> dict[str, Any]:
    return {"id": s.id, "baud": s.baud, "model": s.model, "model_number": s.model_number,
            "firmware": s.firmware, "operating_mode": s.operating_mode,
            "voltage_v": s.voltage_v, "temperature_c": s.temperature_c,
            "hardware_error": s.hardware_error, "unread": list(s.unread)}


def run_scan(args: argparse.Namespace) -> int:
    rig, rig_path = _rig(args)
    with _port(args, rig, rig_path) as port:
        if not args.json:
            print(f"scanning {port} at {', '.join(map(str, args.bauds))} bps ...", flush=True)
        result = _servos(port).scan(args.bauds)
    if args.json:
        print(json.dumps({"port": port, "bauds": result.tried, "collisions": result.collisions,
                          "servos": [_as_dict(s) for s in result.servos]}))
        return 0
    if result.servos:
        print(HEADER)
        for s in result.servos:
            print(_row(s))
    else:
        print("no servo answered at any of these bauds: check power (the servos' LEDs "
              "blink once at power-on), the cable and the adapter's TTL/RS-485 setting "
              "(docs/hardware.md)")
        kind = servo_bringup()
        if set(args.bauds) != set(kind.bauds):
            print("only the bauds of --bauds were looked at: without it, scan tries every "
                  f"baud {kind.family} supports (about 10 s)")
    for baud in result.collisions:
        print(f"at {baud} bps replies were garbled: {servo_bringup().one_at_a_time}")
    counts = {b: len(result.ids_at(b)) for b in result.tried if result.ids_at(b)}
    if len(counts) > 1:
        print("servos answer at more than one baud: a rig runs all of them at one "
              f"([bus] baud = {rig.bus.baud}); move the others with `handrig servos set-baud`")
    return 0


def _baud_of(args: argparse.Namespace, rig: RigConfig) -> int:
    return int(args.baud or rig.bus.baud)


def _found_baud(args: argparse.Namespace, rig: RigConfig, port: str, servo_id: int) -> int:
    """``--baud``, else the baud servo ``servo_id`` answers at (the rig's first)."""
    if args.baud:
        return int(args.baud)
    servos = _servos(port)
    baud = servos.find_baud(servo_id, servos.search_order([rig.bus.baud]))
    print(f"servo {servo_id} answers at {baud} bps", flush=True)
    return baud


def run_set_id(args: argparse.Namespace) -> int:
    rig, rig_path = _rig(args)
    with _port(args, rig, rig_path) as port:
        baud = _found_baud(args, rig, port, args.old_id)
        for line in _servos(port).set_id(baud, args.old_id, args.new_id):
            print(line)
    return 0


def run_set_baud(args: argparse.Namespace) -> int:
    rig, rig_path = _rig(args)
    with _port(args, rig, rig_path) as port:
        baud = _found_baud(args, rig, port, args.id)
        for line in _servos(port).set_baud(baud, args.id, args.new_baud):
            print(line)
    if args.new_baud != rig.bus.baud:
        print(f"note: the rig file runs the bus at {rig.bus.baud} bps ([bus] baud in "
              f"{rig_path})")
    return 0


def run_reboot(args: argparse.Namespace) -> int:
    rig, rig_path = _rig(args)
    with _port(args, rig, rig_path) as port:
        after = _servos(port).reboot(_baud_of(args, rig), args.id)
    print(f"servo {args.id} rebooted; hardware errors now: {after.errors_text}")
    if after.hardware_error:
        print("  the cause is still there (e.g. overheating, or a supply outside the "
              "model's voltage range): remove it, then reboot again")
        return 1
    return 0


def run_check(args: argparse.Namespace) -> int:
    rig, rig_path = _rig(args)
    with _port(args, rig, rig_path) as port:
        if not args.json:
            print(format_sources([rig_file(args.rig)]), flush=True)
        found, findings = _servos(port).check(rig, baud=args.baud)
    simulated = say_if_simulated(args.port or rig.bus.port, out=False)
    if args.json:
        print(json.dumps({"port": port, "simulated": simulated,
                          "servos": [_as_dict(s) for s in found],
                          "findings": [{"id": f.servo_id, "what": f.what, "detail": f.detail,
                                        "fix": f.fix} for f in findings]}))
        return 1 if findings else 0
    where = f"the SIMULATED bus {port} (--port sim)" if simulated else port
    print(f"{len(found)} servo(s) answered on {where} at {args.baud or rig.bus.baud} bps; "
          f"the rig file has {len(rig.servos)}")
    for f in findings:
        print(f"  {f.what}: {f.detail}\n    -> {f.fix}")
    if not findings:
        print("  the bus matches the rig file" + (" (emulated servos: not your hardware)"
                                                  if simulated else ""))
    return 1 if findings else 0
