"""``handrig calibrate servos``: find each servo's zero and write it to the rig file.

For every servo in the rig, the joint is brought to its zero pose (finger
straight, wrist neutral: 0 deg in the vocabulary convention) and the servo's
present position becomes ``zero_ticks``:

* by hand (default): torque stays off; move the joint, press Enter to read
  where it is now, Enter again to accept that reading;
* ``--jog``: torque on; type ``+2`` / ``-0.5`` (joint degrees) to jog the
  servo; the prompt then shows the position it settled at, and Enter accepts
  exactly that; ``s`` skips a servo, ``q`` stops (nothing is written);
* ``--yes``: accept every servo's present position without asking (scripts, tests).

Where it reads and writes: the rig file is ``--config``, by default your own
rig.toml ($XDG_CONFIG_HOME/handrig/rig.toml, ~/.config/handrig when unset) if
there is one, else the installed config/rig.toml. The result goes to ``--out``;
by default back to ``--config`` when that is your own file, and to your own
rig.toml when it started from the installed one, which is never rewritten. Use
it with ``handrig run --config FILE``. Comments and layout are kept; only the
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

from handrig.app.factory import port_process
from handrig.cli.calibrate_glove import calibrate_subparsers
from handrig.clock import Clock, MonotonicClock
from handrig.config.loading import build
from handrig.config.paths import CONFIG_HOME_HELP, config_file, output_for
from handrig.config.rig import RigConfig, load_rig_config
from handrig.devices.servo import DynamixelBus
from handrig.devices.servo.registers import Reg
from handrig.errors import ConfigError, HandrigError


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = calibrate_subparsers(sub).add_parser(
        "servos", help="set each servo's zero (by hand, or jogging) and save it to rig.toml",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--config", default=None, metavar="FILE",
                   help=f"rig file to start from (default: rig.toml in {CONFIG_HOME_HELP}, "
                        "else the installed config/rig.toml)")
    p.add_argument("--bus", default=None, metavar="PORT",
                   help="servo port, or 'sim' for the MuJoCo loopback (default: rig file)")
    p.add_argument("--ids", default=None, metavar="LIST", help="only these servo IDs, e.g. 1,2,7")
    p.add_argument("--jog", action="store_true", help="torque on and jog each servo to zero")
    p.add_argument("--yes", action="store_true",
                   help="accept every present position without asking")
    p.add_argument("--out", default=None, metavar="FILE",
                   help="where to write (default: the --config file if it is yours, else "
                        "rig.toml in the user config directory; the installed file is never "
                        "rewritten)")
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
ACCEPT_TOLERANCE_TICKS = 2  # Enter accepts the shown reading if the servo is still within this
POLL_S = 0.02  # present position is read this often while waiting for the servo to settle
STILL_S = 0.15  # ... and counts as settled after this long within STILL_TICKS
STILL_TICKS = 1
SETTLE_TIMEOUT_S = 3.0


def _ask(prompt: str) -> str:
    print(prompt, end="", flush=True)
    line = sys.stdin.readline()
    if not line:
        raise HandrigError("calibration aborted: no more input (nothing was written)")
    return line.strip()


def settled_position(bus: DynamixelBus, index: int, clock: Clock,
                     timeout_s: float = SETTLE_TIMEOUT_S) -> tuple[int, bool]:
    """Present Position of servo ``index`` once it has stopped moving: (ticks, settled).

    Settled: ``STILL_S`` without a change of more than ``STILL_TICKS``. After
    ``timeout_s`` the last reading is returned with ``settled`` False.
    """
    ticks = bus.read_register(index, Reg.PRESENT_POSITION)
    t_end = clock.now() + timeout_s
    anchor, since = ticks, clock.now()
    while True:
        now = clock.now()
        if now - since >= STILL_S:
            return ticks, True
        if now >= t_end:
            return ticks, False
        clock.sleep(POLL_S)
        ticks = bus.read_register(index, Reg.PRESENT_POSITION)
        if abs(ticks - anchor) > STILL_TICKS:
            anchor, since = ticks, clock.now()


def calibrate(
    bus: DynamixelBus, rig: RigConfig, ids: list[int], *, jog: bool, yes: bool,
    ask: Callable[[str], str] = _ask, say: Callable[[str], None] = print,
    clock: Clock | None = None,
) -> dict[int, int]:
    """Walk through the servos and return {id: new zero_ticks}.

    The prompt shows the servo's position read after it settled (after a jog,
    or after the joint was moved by hand); Enter accepts exactly that reading,
    once a fresh read confirms the servo is still there (else the new reading
    is shown and Enter is asked for again).
    """
    clock = clock or MonotonicClock()
    zeros: dict[int, int] = {}
    for servo_id in ids:
        index = bus.ids.index(servo_id)
        cal = rig.servo(servo_id)
        name = bus.describe(index)
        start = bus.read_register(index, Reg.PRESENT_POSITION)
        shown, settled = settled_position(bus, index, clock)
        while True:
            if yes:
                zeros[servo_id] = shown
                say(f"{name}: zero_ticks {cal.zero_ticks} -> {shown}")
                break
            hint = ("+N/-N jog degrees, " if jog else "move the joint by hand, ") + \
                "Enter accepts the position shown, s skips, q quits"
            moving = "" if settled else ", still moving"
            answer = ask(f"{name}: at {shown} ticks ({cal.ticks_to_deg(shown):+.1f} deg from "
                         f"the current zero {cal.zero_ticks}{moving}); bring it to 0 deg "
                         f"[{hint}]: ")
            if answer == "":
                now_ticks, settled = settled_position(bus, index, clock)
                if settled and abs(now_ticks - shown) <= ACCEPT_TOLERANCE_TICKS:
                    zeros[servo_id] = shown
                    say(f"{name}: zero_ticks {cal.zero_ticks} -> {shown}")
                    break
                say(f"{name}: it moved ({shown} -> {now_ticks} ticks); Enter accepts the new "
                    "position if it stays")
                shown = now_ticks
                continue
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
            shown, settled = settled_position(bus, index, clock)
    return zeros


def run(args: argparse.Namespace) -> int:
    rig_path = Path(args.config) if args.config else config_file("rig.toml")
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
    out = Path(args.out) if args.out else output_for(rig_path, "rig.toml")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    print(f"wrote {len(zeros)} zero(s) to {out}")
    moved = out.resolve().parent != rig_path.resolve().parent
    relative = [f"{k} = {v!r}" for k in ("map", "sag_grid", "glove")
                if (v := getattr(rig.loop, k)) and not Path(v).is_absolute()]
    if moved and relative:
        print(f"  note: {', '.join(relative)} in [loop] are relative to the rig file's "
              f"folder, now {out.parent}")
    print(f"  use it with: handrig run --config {out}")
    return 0
