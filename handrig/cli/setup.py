"""``handrig setup``: from a plugged-in servo adapter to a rig that runs.

Three steps, each skippable:

1. the port: unplug the adapter when asked and plug it back in; the port that
   went away is the adapter's (its ``/dev/serial/by-id/`` name, which stays the
   same, is what gets written). ``--port PORT`` skips this step.
2. your rig file gets it as ``[bus] port``: your own rig.toml
   ($XDG_CONFIG_HOME/handrig, a copy of the shipped one the first time; the
   shipped file is never rewritten), with a dated backup (``handrig calibrate
   undo`` puts it back). ``--out FILE`` writes elsewhere.
3. the servos (``--no-servos`` skips): one new servo at a time, for each servo of
   the rig in order (``--ids`` for some): plug it in, it is found at whatever ID
   and baud it has (new ones answer as ID 1 at 57600 bps), given its ID and the
   rig's baud, torque off, next. Then ``handrig servos check`` compares the bus
   with the rig file (exit 1 when anything differs).

Then: ``handrig calibrate servos`` finds each servo's zero.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from handrig.app.sources import rig_file
from handrig.cli._ports import by_id_for
from handrig.cli._rig import add_rig_argument
from handrig.cli.calibrate_servos import default_out
from handrig.config.paths import user_config
from handrig.config.rig import RigConfig
from handrig.config.toml_edit import edit, write_with_backup
from handrig.errors import ConfigError
from handrig.pose.robot_rig import RobotRigConfig, load_rig


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "setup", help="from a plugged-in servo adapter to a working rig file: find the "
        "port, write it, give new servos their IDs and baud",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_rig_argument(p, old_name=False)
    p.add_argument("--port", default=None, metavar="PORT",
                   help="the adapter's port (skips finding it by unplugging)")
    p.add_argument("--out", default=None, metavar="FILE",
                   help="the rig file to write (default: your own rig.toml, copied from "
                   "the shipped one the first time; the shipped file is never rewritten)")
    p.add_argument("--ids", default=None, metavar="LIST",
                   help="only these servo IDs, in this order, e.g. 1,2,7 (default: the "
                   "rig's, in order)")
    p.add_argument("--bauds", default=None, metavar="LIST",
                   help="look for new servos at these bauds, in order (default: the rig's, "
                   "57600, the fast ones, 9600 last)")
    p.add_argument("--no-servos", action="store_true",
                   help="only find the port and write it; no servo is touched")
    p.set_defaults(func=run)


def _ask(prompt: str) -> str:
    try:
        return input(prompt)
    except EOFError:
        return "q"


def run(args: argparse.Namespace, *, ask: Callable[[str], str] = _ask,
        say: Callable[[str], None] = print,
        list_ports: Callable[[], Sequence[str]] | None = None) -> int:
    """The steps (module docstring). ``ask``, ``say`` and ``list_ports`` (the port
    lister of step 1, default :func:`~handrig.app.setup_wizard.serial_ports`) are the
    person and the machine; a test passes its own."""
    from handrig.app import setup_wizard as wizard
    from handrig.app.factory import servo_bringup

    kind = servo_bringup()
    source = rig_file(args.rig)
    rig = load_rig(source.path)
    ids = _ids(args.ids, [s.id for s in rig.servos])
    if args.port == "sim":
        raise ConfigError("setup writes your rig file for the hardware; the simulated rig "
                          "needs none", key="--port", value="sim",
                          allowed="the adapter's port, or none to find it by unplugging; "
                          "give --port sim to each command to use the simulated rig")
    bauds = _bauds(args.bauds, kind.bauds, kind.family)  # before anything is written
    try:
        say("step 1: the servo adapter's port")
        if args.port:
            port = args.port
            say(f"  {port} (--port)")
        else:
            port = wizard.find_port(list_ports or wizard.serial_ports, ask, say,
                                    stable_name=by_id_for)
        out = Path(args.out) if args.out else default_out(source.path)
        say(f"step 2: the rig file: [bus] port = {port!r} -> {out}")
        _write_port(source.path, out, port, rig, say)
        if args.no_servos:
            return 0
        say(f"step 3: the servos, one at a time: {len(ids)} to do, each given its ID and "
            f"{rig.bus.baud} bps")
        servos = kind(port)
        done = wizard.commission_servos(servos, rig, ids, ask, say, bauds=bauds)
    except wizard.Quit:
        say("setup stopped: what was done stays done (the rig file, servos made ready)")
        return 1
    say(f"{len(done.ready)} servo(s) made ready" +
        (f", skipped: {', '.join(map(str, done.skipped))}" if done.skipped else ""))
    say("with all of them chained: `handrig servos check` ...")
    found, findings = servos.check(load_rig(out))
    say(f"{len(found)} servo(s) answered on {port} at {rig.bus.baud} bps; the rig file has "
        f"{len(rig.servos)}")
    for f in findings:
        say(f"  {f.what}: {f.detail}\n    -> {f.fix}")
    if findings:
        return 1
    say("  the bus matches the rig file. Next: `handrig calibrate servos` finds each "
        "servo's zero")
    return 0


def _bauds(text: str | None, supported: Sequence[int], family: str) -> list[int] | None:
    """``--bauds``: each one of ``supported`` (the bauds ``family`` takes), else None."""
    if not text:
        return None
    try:
        bauds = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        bauds = [-1]
    if not bauds or any(b not in supported for b in bauds):
        raise ConfigError(f"not a list of bauds {family} supports", key="--bauds",
                          value=text, allowed=", ".join(map(str, supported)))
    return bauds


def _ids(text: str | None, ids: list[int]) -> list[int]:
    if not text:
        return ids
    try:
        wanted = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ConfigError("not a list of servo IDs", key="--ids", value=text) from None
    unknown = sorted(set(wanted) - set(ids))
    if unknown:
        raise ConfigError("servo IDs not in the rig file", key="--ids", value=unknown,
                          allowed=", ".join(map(str, ids)))
    return wanted


def _write_port(rig_path: Path, out: Path, port: str, rig: RigConfig,
                say: Callable[[str], None]) -> None:
    """``[bus] port`` of ``rig_path``'s text set to ``port``, written to ``out`` with a
    backup (a preset copied elsewhere keeps its robot model and table where they are)."""
    text = edit(rig_path.read_text(encoding="utf-8"),
                lambda doc: doc["bus"].__setitem__("port", port), file=str(rig_path))
    robot = rig.robot if isinstance(rig, RobotRigConfig) else None
    if out.resolve().parent != rig_path.resolve().parent and robot is not None:
        text = edit(text, lambda doc: doc["robot"].update(
            model=str(robot.model), retarget=str(robot.retarget)), file=str(rig_path))
    out.parent.mkdir(parents=True, exist_ok=True)
    backup = write_with_backup(out, text)
    say(f"  wrote {out} (backup of what was there: {backup}; `handrig calibrate undo "
        f"--file {out}` puts it back)")
    if out.resolve() == user_config("rig.toml").resolve():
        say("  every command reads it from now on (your rig.toml)")
