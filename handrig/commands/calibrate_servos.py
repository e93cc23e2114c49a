"""``handrig calibrate servos``: find each servo's zero and write it to the rig file.

For every servo in the rig, the joint is brought to its zero pose (finger
straight, wrist neutral: 0 deg in the vocabulary convention) and the servo's
present position becomes ``zero_ticks``:

* by hand (default): torque stays off; move the joint, press Enter;
* ``--jog``: torque on; type ``+2`` / ``-0.5`` (joint degrees) to jog the servo,
  Enter to accept; ``s`` skips a servo, ``q`` stops (nothing is written);
* ``--yes``: accept every servo's present position without asking (scripts, tests).

The rig file is rewritten in place, keeping its comments; only the
``zero_ticks`` lines change, and the new file is checked before it is written
(a zero whose limits fall outside the servo's range is refused with the reason).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import re
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from handrig.app import port_process
from handrig.commands.calibrate_glove import calibrate_subparsers
from handrig.config import CONFIG_DIR, build
from handrig.errors import ConfigError, HandrigError
from handrig.rigconfig import RigConfig, load_rig_config
from handrig.servo import DynamixelBus
from handrig.servo.registers import Reg


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = calibrate_subparsers(sub).add_parser(
        "servos", help="set each servo's zero (by hand, or jogging) and save it to rig.toml",
        description=__doc__,
    )
    p.add_argument("--config", default=None, metavar="FILE",
                   help="rig file to update (default config/rig.toml)")
    p.add_argument("--bus", default=None, metavar="PORT",
                   help="servo port, or 'sim' for the MuJoCo loopback (default: rig file)")
    p.add_argument("--ids", default=None, metavar="LIST", help="only these servo IDs, e.g. 1,2,7")
    p.add_argument("--jog", action="store_true", help="torque on and jog each servo to zero")
    p.add_argument("--yes", action="store_true",
                   help="accept every present position without asking")
    p.add_argument("--out", default=None, metavar="FILE",
                   help="write here instead of rewriting the rig file")
    p.set_defaults(func=run)


def update_zero_ticks(text: str, zeros: dict[int, int]) -> str:
    """``text`` of a rig file with ``zero_ticks`` of the given servo IDs replaced.

    Works on the ``[[servos]]`` blocks line by line, so comments and layout stay; a
    block without a ``zero_ticks`` line gets one after its ``id`` line.
    """
    lines = text.splitlines(keepends=True)
    # (first line, end line) of every [[servos]] block
    blocks: list[tuple[int, int]] = []
    begin: int | None = None
    for i, line in enumerate(lines):
        header = line.split("#", 1)[0].strip()
        if re.fullmatch(r"\[\[?\s*[A-Za-z_][\w.\- ]*\]\]?", header):  # a table header
            if begin is not None:
                blocks.append((begin, i))
                begin = None
            if re.fullmatch(r"\[\[\s*servos\s*\]\]", header):
                begin = i
    if begin is not None:
        blocks.append((begin, len(lines)))
    by_id: dict[int, tuple[int | None, int]] = {}  # id -> (zero line, id line)
    for first, last in blocks:
        id_line = zero_at = None
        servo_id = None
        for i in range(first + 1, last):
            stripped = lines[i].strip()
            m = re.match(r"id\s*=\s*(\d+)", stripped)
            if m:
                servo_id, id_line = int(m.group(1)), i
            elif re.match(r"zero_ticks\s*=", stripped):
                zero_at = i
        if servo_id is not None and id_line is not None:
            by_id[servo_id] = (zero_at, id_line)
    for servo_id in zeros:
        if servo_id not in by_id:
            raise ConfigError("no [[servos]] block with this id", key="servos.id", value=servo_id)
    inserts: list[tuple[int, str]] = []
    for servo_id, ticks in zeros.items():
        zero_at, id_line = by_id[servo_id]
        if zero_at is not None:
            old = lines[zero_at]
            indent = old[: len(old) - len(old.lstrip())]
            comment = "  " + old[old.index("#"):].rstrip("\n") if "#" in old else ""
            lines[zero_at] = f"{indent}zero_ticks = {ticks}{comment}\n"
        else:
            inserts.append((id_line + 1, f"zero_ticks = {ticks}\n"))
    for at, line in sorted(inserts, reverse=True):
        lines.insert(at, line)
    return "".join(lines)


def calibration_rig(rig: RigConfig) -> RigConfig:
    """The rig as calibration uses it: a person answers the prompts, so no Bus Watchdog
    (it would trip between two jogs and the servo would refuse the next goal)."""
    return dataclasses.replace(rig, bus=dataclasses.replace(rig.bus, watchdog_ms=0))


MAX_JOG_STEP_DEG = 10.0  # one jog command moves the joint at most this far


def _ask(prompt: str) -> str:
    print(prompt, end="", flush=True)
    line = sys.stdin.readline()
    if not line:
        raise HandrigError("calibration aborted: no more input (nothing was written)")
    return line.strip()


def calibrate(
    bus: DynamixelBus, rig: RigConfig, ids: list[int], *, jog: bool, yes: bool,
    ask: Callable[[str], str] = _ask, say: Callable[[str], None] = print,
) -> dict[int, int]:
    """Walk through the servos and return {id: new zero_ticks}."""
    zeros: dict[int, int] = {}
    for servo_id in ids:
        index = bus.ids.index(servo_id)
        cal = rig.servo(servo_id)
        name = bus.describe(index)
        start = bus.read_register(index, Reg.PRESENT_POSITION)
        while True:
            ticks = bus.read_register(index, Reg.PRESENT_POSITION)
            deg = cal.ticks_to_deg(ticks)
            if yes:
                answer = ""
            else:
                hint = ("+N/-N jog degrees, " if jog else "move the joint by hand, ") + \
                    "Enter accepts, s skips, q quits"
                answer = ask(f"{name}: present {ticks} ticks ({deg:+.1f} deg from the "
                             f"current zero {cal.zero_ticks}); bring it to 0 deg [{hint}]: ")
            if answer == "":
                ticks = bus.read_register(index, Reg.PRESENT_POSITION)  # where it is now
                zeros[servo_id] = int(ticks)
                say(f"{name}: zero_ticks {cal.zero_ticks} -> {ticks}")
                break
            if answer.lower() == "s":
                say(f"{name}: skipped (zero_ticks stays {cal.zero_ticks})")
                break
            if answer.lower() == "q":
                raise HandrigError("calibration stopped: nothing was written")
            if jog:
                try:
                    step_deg = float(answer)
                except ValueError:
                    step_deg = math.nan
                if not math.isfinite(step_deg) or abs(step_deg) > MAX_JOG_STEP_DEG:
                    say(f"not a jog: {answer!r}; type degrees between -{MAX_JOG_STEP_DEG:g} "
                        f"and +{MAX_JOG_STEP_DEG:g}, e.g. +2 or -0.5")
                    continue
                ticks_per_deg = cal.direction * cal.gear_ratio * 4096 / 360
                base = bus.read_register(index, Reg.GOAL_POSITION)  # jogs add up
                goal = round(base + ticks_per_deg * step_deg)
                # never further from where it started than the joint's configured span
                span = abs(ticks_per_deg) * (cal.max_deg - cal.min_deg)
                low, high = max(0, start - span), min(4095, start + span)
                bus.write_register(index, Reg.GOAL_POSITION, int(min(max(goal, low), high)))
            else:
                say("torque is off: move the joint by hand, then press Enter")
    return zeros


def run(args: argparse.Namespace) -> int:
    rig_path = Path(args.config) if args.config else CONFIG_DIR / "rig.toml"
    rig = load_rig_config(rig_path)
    ids = [s.id for s in rig.servos]
    if args.ids:
        try:
            wanted = [int(x) for x in args.ids.split(",") if x.strip()]
        except ValueError:
            raise ConfigError("not a list of servo IDs", key="--ids", value=args.ids) from None
        unknown = sorted(set(wanted) - set(ids))
        if unknown:
            raise ConfigError("servo IDs not in the rig file", key="--ids", value=unknown,
                              allowed=", ".join(map(str, ids)))
        ids = wanted
    bus_spec = args.bus or rig.bus.port
    with contextlib.ExitStack() as stack:
        if bus_spec == "sim":
            _, bus_spec = stack.enter_context(
                port_process(["sim-bus", "--rig", str(rig_path)], "the simulated servo bus"))
        bus = DynamixelBus(bus_spec, calibration_rig(rig))
        bus.hold_outside_limits = True  # the zero is what is being found
        stack.callback(bus.close)
        bus.connect()
        if args.jog:
            with bus.torque():
                zeros = calibrate(bus, rig, ids, jog=True, yes=args.yes)
        else:
            bus.disable_torque()
            zeros = calibrate(bus, rig, ids, jog=False, yes=args.yes)
    text = update_zero_ticks(rig_path.read_text(), zeros)
    try:
        build(RigConfig, tomllib.loads(text))
    except ConfigError as exc:
        raise ConfigError(f"the new zeros do not fit: {exc.detail}", key=exc.key,
                          value=exc.value, allowed=exc.allowed) from None
    out = Path(args.out) if args.out else rig_path
    out.write_text(text)
    print(f"wrote {len(zeros)} zero(s) to {out}")
    return 0
