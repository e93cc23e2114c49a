"""``handrig calibrate servos``: find each servo's zero and write it to the rig file.

For every servo in the rig, the joint is brought to its zero pose (finger
straight, wrist neutral: 0 deg in the vocabulary convention) and the servo's
present position becomes ``zero_ticks``. Two steps per servo, read then accept:

* by hand (default): torque stays off; move the joint, press Enter to read where
  it is; the new zero and its shift from the current one are shown; Enter again
  accepts exactly that reading (r reads again);
* ``--jog``: torque on; type ``+2`` / ``-30`` (joint degrees, up to the joint's
  range) to jog the servo, Enter to read where it settled, Enter again to accept;
* ``s`` skips a servo; ``q`` leaves: nothing is written, exit status 0;
* ``--yes``: read and accept every servo's present position without asking
  (scripts, tests), except the ones that need a confirmation, which are skipped.

A confirmation (typing ``yes``) is needed, and the reason shown, when the new zero
is further than ``[calibration] max_zero_shift_deg`` (default 20) from the current
one (a joint hanging under gravity with torque off, or a horn a spline off, reads
like that), or when it puts part of ``[min_deg, max_deg]`` outside the servo's
travel (the limits are then narrowed to what the servo can reach).

After a zero is accepted the direction is checked: with ``--jog`` the servo moves
the joint a few degrees towards flexion and asks whether it flexed; by hand you
flex it and the reading's sign is checked. A wrong direction flips ``direction``
(after you agree). ``--no-direction-check`` leaves it out.

Where it reads and writes: the rig file is ``--rig``, by default your own
rig.toml ($XDG_CONFIG_HOME/handrig/rig.toml, ~/.config/handrig when unset) if
there is one, else the installed config/rig.toml. The result goes to ``--out``;
by default back to the rig file when it is your own, and to your own rig.toml
when it started from the installed one, which is never rewritten (``handrig run``
then reads it without being told). Comments and layout are kept; only the
changed values are rewritten, and the new file is checked before it is written.
Every write first keeps a dated copy of the file in ``backups/`` beside it;
``handrig calibrate undo`` puts the last one back, byte for byte.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from handrig.app.factory import zeroing_bus
from handrig.app.sources import Source, format_sources, rig_file
from handrig.cli._display import check_gl_backend
from handrig.cli._ports import say_if_simulated
from handrig.cli._rig import add_rig_argument
from handrig.cli.calibrate_glove import calibrate_subparsers
from handrig.clock import Clock, MonotonicClock
from handrig.config.loading import build
from handrig.config.paths import is_installed, output_for, user_config, user_config_dir
from handrig.config.rig import RigConfig, ServoCalibration, require_port
from handrig.config.toml_edit import (
    BACKUP_DIR,
    backups_of,
    edit,
    undo,
    update_servos,
    write_with_backup,
)
from handrig.devices.servo.zeroing import Proposal, ZeroingBus
from handrig.errors import ConfigError, HandrigError
from handrig.pose.robot_rig import load_rig


def register(sub: Any) -> None:
    calibrate = calibrate_subparsers(sub)
    p: argparse.ArgumentParser = calibrate.add_parser(
        "servos", help="set each servo's zero (by hand, or jogging) and save it to rig.toml",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_rig_argument(p)
    p.add_argument("--port", "--bus", dest="bus", default=None, metavar="PORT",
                   help="servo port, or 'sim' for the simulated rig (its zeros are the "
                   "emulator's, not your hardware's); default: the rig file's [bus] port "
                   "(--bus is the older name)")
    p.add_argument("--ids", default=None, metavar="LIST", help="only these servo IDs, e.g. 1,2,7")
    p.add_argument("--jog", action="store_true", help="torque on and jog each servo to zero")
    p.add_argument("--yes", action="store_true",
                   help="accept every present position without asking (a zero that needs a "
                   "confirmation is skipped)")
    p.add_argument("--no-direction-check", action="store_true",
                   help="do not check each servo's direction after its zero")
    p.add_argument("--out", default=None, metavar="FILE",
                   help="where to write (default: the rig file if it is yours, else "
                        "rig.toml in the user config directory; the installed file is never "
                        "rewritten)")
    p.set_defaults(func=run)
    u: argparse.ArgumentParser = calibrate.add_parser(
        "undo", help="put back the file as it was before the last calibration wrote it",
        description="Restore the newest backup (byte for byte) of a file a calibration "
        "wrote, and delete that backup: a second undo goes one write further back. "
        "Default: whichever of your files in the user config directory a calibration "
        "wrote last.")
    u.add_argument("--file", default=None, metavar="FILE",
                   help="the calibrated file (default: the one of yours written last)")
    u.set_defaults(func=run_undo)


def update_zero_ticks(text: str, zeros: dict[int, int]) -> str:
    """``text`` of a rig file with ``zero_ticks`` of the given servo IDs replaced
    (comments and layout kept)."""
    return update_servos(text, {i: {"zero_ticks": t} for i, t in zeros.items()})


ACCEPT_TOLERANCE_TICKS = 2  # Enter accepts the shown reading if the servo is still within this
POLL_S = 0.02  # present position is read this often while waiting for the servo to settle
STILL_S = 0.15  # ... and counts as settled after this long within STILL_TICKS
STILL_TICKS = 1
SETTLE_TIMEOUT_S = 3.0
DIRECTION_STEP_DEG = 10.0  # the direction check moves the joint this far (within its limits)
DIRECTION_MIN_DEG = 3.0  # by hand: a flex must read at least this far from zero


class Quit(Exception):
    """The user typed q: leave, nothing written."""


def _ask(prompt: str) -> str:
    print(prompt, end="", flush=True)
    line = sys.stdin.readline()
    if not line:
        raise HandrigError("calibration aborted: no more input (nothing was written)")
    return line.strip()


def settled_position(bus: ZeroingBus, index: int, clock: Clock,
                     timeout_s: float = SETTLE_TIMEOUT_S) -> tuple[int, bool]:
    """Present Position of servo ``index`` once it has stopped moving: (ticks, settled).

    Settled: ``STILL_S`` without a change of more than ``STILL_TICKS``. After
    ``timeout_s`` the last reading is returned with ``settled`` False.
    """
    ticks = bus.position(index)
    t_end = clock.now() + timeout_s
    anchor, since = ticks, clock.now()
    while True:
        now = clock.now()
        if now - since >= STILL_S:
            return ticks, True
        if now >= t_end:
            return ticks, False
        clock.sleep(POLL_S)
        ticks = bus.position(index)
        if abs(ticks - anchor) > STILL_TICKS:
            anchor, since = ticks, clock.now()


def _jog(bus: ZeroingBus, index: int, cal: ServoCalibration, start: int,
         answer: str, say: Callable[[str], None]) -> bool:
    """Jog by ``answer`` joint degrees, at most the joint's range; False if not a jog."""
    span_deg = cal.max_deg - cal.min_deg
    try:
        step_deg = float(answer)
    except ValueError:
        step_deg = math.nan
    if not math.isfinite(step_deg) or abs(step_deg) > span_deg:
        say(f"not a jog: {answer!r}; type degrees between -{span_deg:g} and +{span_deg:g} "
            "(the joint's range), e.g. +2 or -30")
        return False
    bus.jog(index, cal, start, step_deg)
    return True


def check_direction(bus: ZeroingBus, index: int, cal: ServoCalibration, *, jog: bool,
                    ask: Callable[[str], str], say: Callable[[str], None],
                    clock: Clock) -> int | None:
    """Check ``cal.direction`` (``cal`` has the new zero); the direction to write if it
    must flip, else None. Jogging: the servo flexes the joint and the user says whether
    it flexed. By hand: the user flexes it and the reading's sign tells."""
    name = bus.describe(index)
    step = min(DIRECTION_STEP_DEG, cal.max_deg) if cal.max_deg > 0 else 0.0
    flip = -cal.direction
    if jog:
        if step <= 0:
            say(f"{name}: its range [{cal.min_deg:g}, {cal.max_deg:g}] allows no flexion: "
                "direction not checked")
            return None
        bus.move_to_deg(index, cal, step)
        settled_position(bus, index, clock)
        try:
            while True:
                answer = ask(f"{name}: moved to {step:+g} deg. Did the joint flex (bend the way "
                             "it closes)? [y/n, q quits]: ").lower()
                if answer in ("y", "yes"):
                    return None
                if answer in ("n", "no"):
                    say(f"{name}: direction flips to {flip} (it moved the other way)")
                    return flip
                if answer == "q":
                    raise Quit
        finally:
            bus.move_to_deg(index, cal, 0.0)
            settled_position(bus, index, clock)
    while True:
        answer = ask(f"{name}: direction check: flex the joint by hand (bend it the way it "
                     "closes, 10 deg or more), hold it, press Enter [s skips the check, q "
                     "quits]: ").lower()
        if answer == "s":
            say(f"{name}: direction not checked")
            return None
        if answer == "q":
            raise Quit
        ticks, _ = settled_position(bus, index, clock)
        deg = bus.joint_deg(cal, ticks)
        if abs(deg) < DIRECTION_MIN_DEG:
            say(f"{name}: it reads {deg:+.1f} deg: flex it further (s skips the check; "
                "with --jog the servo moves the joint and you say which way it went)")
            continue
        if deg > 0:
            say(f"{name}: reads {deg:+.1f} deg where you flexed it: direction {cal.direction} "
                "is right")
            return None
        answer = ask(f"{name}: reads {deg:+.1f} deg where you flexed it: the direction looks "
                     f"reversed. Write direction = {flip}? [y/n]: ").lower()
        if answer in ("y", "yes"):
            return flip
        say(f"{name}: direction stays {cal.direction}")
        return None


def calibrate(
    bus: ZeroingBus, rig: RigConfig, ids: list[int], *, jog: bool, yes: bool,
    ask: Callable[[str], str] = _ask, say: Callable[[str], None] = print,
    clock: Clock | None = None, direction_check: bool = True,
) -> dict[int, dict[str, Any]]:
    """Walk through the servos; return {id: {key: new value}} (``zero_ticks``, and
    ``direction``, ``min_deg``/``max_deg`` where they change). Raises :class:`Quit`.

    Step one shows the servo's settled position; Enter reads it. Step two shows the
    reading as a new zero, with its shift; Enter accepts exactly that reading once a
    fresh read confirms the servo is still there (else the new reading is shown).
    A zero that needs a confirmation (see :meth:`ZeroingBus.propose`) is accepted only by
    typing ``yes``; ``yes=True`` skips those servos.
    """
    clock = clock or MonotonicClock()
    bound = rig.calibration.max_zero_shift_deg
    changes: dict[int, dict[str, Any]] = {}
    for servo_id in ids:
        index = bus.ids.index(servo_id)
        cal = rig.servo(servo_id)
        name = bus.describe(index)
        start = bus.position(index)
        shown, settled = settled_position(bus, index, clock)
        reading: int | None = shown if yes else None
        hint = "+N/-N jog degrees, " if jog else "move the joint by hand, "
        accepted: Proposal | None = None
        while accepted is None:
            if reading is None:
                moving = "" if settled else ", still moving"
                answer = ask(f"{name}: at {shown} ticks ({bus.joint_deg(cal, shown):+.1f} deg "
                             f"from the current zero {cal.zero_ticks}{moving}); bring it to "
                             f"0 deg [{hint}Enter reads it, s skips, q quits]: ")
            else:
                prop = bus.propose(cal, reading, bound)
                say(f"{name}: reads {reading} ticks: zero_ticks {cal.zero_ticks} -> {reading} "
                    f"({prop.shift_deg:+.1f} deg)")
                if prop.impossible:
                    say(f"{name}: cannot be the zero: {prop.impossible}")
                    if yes:
                        break
                    reading = None
                    continue
                else:
                    for reason in prop.reasons:
                        say(f"{name}: needs a confirmation: {reason}")
                    if yes:
                        if prop.reasons:
                            say(f"{name}: not written (--yes does not confirm); run without "
                                "--yes to confirm it")
                            break
                        accepted = prop
                        continue
                    answer = ask(f"{name}: type yes to accept this zero anyway, Enter reads "
                                 "again, s skips, q quits: " if prop.reasons else
                                 f"{name}: Enter accepts this zero, r reads again, s skips, "
                                 "q quits: ")
                    confirm = answer.lower() == "yes" if prop.reasons else answer == ""
                    if confirm:
                        now_ticks, settled = settled_position(bus, index, clock)
                        if settled and abs(now_ticks - reading) <= ACCEPT_TOLERANCE_TICKS:
                            accepted = prop
                            continue
                        say(f"{name}: it moved ({reading} -> {now_ticks} ticks); read again")
                        shown, reading = now_ticks, None
                        continue
                    if answer in ("", "r"):
                        reading = None
                        shown, settled = settled_position(bus, index, clock)
                        continue
            low = answer.lower()
            if low == "q":
                raise Quit
            if low == "s":
                say(f"{name}: skipped (zero_ticks stays {cal.zero_ticks})")
                break
            if answer in ("", "r"):
                shown, settled = settled_position(bus, index, clock)
                reading = shown
                continue
            if jog:
                reading = None
                if _jog(bus, index, cal, start, answer, say):
                    shown, settled = settled_position(bus, index, clock)
                continue
            say("torque is off: move the joint by hand, then press Enter")
            shown, settled = settled_position(bus, index, clock)
        if accepted is None:
            continue
        change: dict[str, Any] = {"zero_ticks": accepted.zero_ticks}
        new_cal = dataclasses.replace(cal, zero_ticks=accepted.zero_ticks)
        if accepted.limits_deg is not None:
            change["min_deg"], change["max_deg"] = accepted.limits_deg
            new_cal = dataclasses.replace(new_cal, min_deg=accepted.limits_deg[0],
                                          max_deg=accepted.limits_deg[1])
        say(f"{name}: zero_ticks {cal.zero_ticks} -> {accepted.zero_ticks} accepted"
            + (f", limits [{new_cal.min_deg:g}, {new_cal.max_deg:g}] deg"
               if accepted.limits_deg else ""))
        if direction_check and not yes:
            flipped = check_direction(bus, index, new_cal, jog=jog, ask=ask, say=say,
                                      clock=clock)
            if flipped is not None:
                change["direction"] = flipped
        changes[servo_id] = change
    return changes


def default_out(rig_path: Path) -> Path:
    """Where a calibration of ``rig_path`` goes by default: the file itself when it is
    yours; your rig.toml for the installed default; your copy of a preset by its name."""
    if is_installed(rig_path) and rig_path.name != "rig.toml":
        return user_config(rig_path.name)
    return output_for(rig_path, "rig.toml")


def run(args: argparse.Namespace) -> int:
    source = rig_file(args.rig)
    rig_path = source.path
    rig = load_rig(rig_path)
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
    out = Path(args.out) if args.out else default_out(rig_path)
    bus_spec = require_port(args.bus or rig.bus.port, rig_path)
    simulated = say_if_simulated(bus_spec)
    print(format_sources([source, Source("writes to", out, "--out" if args.out else
                                         "default: your own copy, with a dated backup")]),
          flush=True)
    if simulated:
        print(f"  the zeros read here are the EMULATED servos': written to {out} as any "
              "calibration (`handrig calibrate undo` puts it back); nobody can flex an "
              "emulated joint: at the direction check press s, or use --jog", flush=True)
        check_gl_backend("--port sim")
    try:
        with zeroing_bus(bus_spec, rig, rig_path) as bus:
            bus.connect()
            check = not args.no_direction_check
            if args.jog:
                with bus.torque():
                    changes = calibrate(bus, rig, ids, jog=True, yes=args.yes,
                                        direction_check=check)
            else:
                bus.relax()
                changes = calibrate(bus, rig, ids, jog=False, yes=args.yes,
                                    direction_check=check)
    except Quit:
        print("calibration stopped: nothing was written")
        return 0
    if not changes:
        print("nothing to write: no servo's zero was accepted")
        return 0
    text = update_servos(rig_path.read_text(encoding="utf-8"), changes, file=str(rig_path))
    moved = out.resolve().parent != rig_path.resolve().parent
    robot = getattr(rig, "robot", None)
    if moved and robot is not None:  # a preset's copy: its model and table stay where they are
        text = edit(text, lambda doc: doc["robot"].update(
            model=str(robot.model), retarget=str(robot.retarget)), file=str(rig_path))
    try:
        build(type(rig), tomllib.loads(text))
    except ConfigError as exc:
        raise ConfigError(f"the new zeros do not fit: {exc.detail}", key=exc.key,
                          value=exc.value, allowed=exc.allowed) from None
    out.parent.mkdir(parents=True, exist_ok=True)
    backup = write_with_backup(out, text)
    print(f"wrote {len(changes)} servo calibration(s) to {out}"
          + (" (SIMULATED: the emulator's zeros, not your hardware's)" if simulated else ""))
    print(f"  backup of what was there: {backup} (`handrig calibrate undo` puts it back)")
    relative = [f"{k} = {v!r}" for k in ("map", "sag_grid", "glove")
                if (v := getattr(rig.loop, k)) and not Path(v).is_absolute()]
    if moved and relative:
        print(f"  note: {', '.join(relative)} in [loop] are relative to the rig file's "
              f"folder, now {out.parent}")
    if out.resolve() == user_config("rig.toml").resolve():
        print("  `handrig run` and `handrig demo` read it from now on (your rig.toml)")
    else:
        print(f"  use it with: handrig run --rig {out}")
    return 0


def run_undo(args: argparse.Namespace) -> int:
    if args.file:
        target = Path(args.file)
    else:
        folder = user_config_dir()
        names = {p.name.split(".20", 1)[0] for p in (folder / BACKUP_DIR).glob("*.toml.*")}
        dated = [(backups_of(folder / n)[-1].name[len(n) + 1:], folder / n) for n in names
                 if backups_of(folder / n)]
        if not dated:
            raise ConfigError("no calibration to undo: no backups of your files",
                              file=str(folder / BACKUP_DIR),
                              allowed="--file FILE for a file written with --out")
        target = max(dated)[1]  # the one written last
    print(undo(target))
    return 0
