"""The ``handrig`` command line.

Subcommands are the modules of this package (one per subcommand; names
starting with ``_`` are shared helpers): every module has a
``register(subparsers)`` function that adds its parser and sets ``func`` (a
callable taking the parsed namespace and returning an exit status). Errors
handrig raises on purpose print one line and exit 2; never a traceback.

A run imports only the module(s) of the command it was given (:data:`COMMANDS`
lists each command's help line and modules); the others stand in the parser as
their name and help line, so ``handrig --help`` and a command's start do not pay
for importing MuJoCo, numba and scipy through every other command.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import pkgutil
import sys
from collections.abc import Sequence

from handrig import __version__
from handrig.errors import HandrigError
from handrig.realtime import apply_cpus_from_env

COMMANDS: dict[str, tuple[str, tuple[str, ...]]] = {
    # command: (its help line, the modules whose register() adds it, in module order)
    "analyze": ("ranges, rmsd1/rmsd2 and the four simplification steps (Tables 1-5) of a BVH",
                ("analyze",)),
    "bake": ("bake the passive-sag grid (23 DOFs over forearm inclination x rotation)",
             ("bake",)),
    "bench": ("benchmarks against the emulators", ("bench_bus",)),
    "calibrate": ("calibrate the glove or the servos and write the config files",
                  ("calibrate_glove", "calibrate_servos")),
    "config": ("show the configuration a run uses, and where each value comes from",
               ("config_show",)),
    "demo": ("the embedded demo: a recorded glove drives the simulated puppet", ("demo",)),
    "evaluate": ("RMS error of a map against a BVH's own curves; methods side by side",
                 ("evaluate",)),
    "expand": ("expand a BVH's control curves into all 50 curves through a map (CSV)",
               ("expand",)),
    "fit-map": ("fit a map from control curves (a glove's channels) to all 50 curves",
                ("fit_map",)),
    "glove": ("look at the glove: `handrig glove monitor`", ("glove_monitor",)),
    "joints": ("list the 50 curves and 23 DOFs per hand, with axes and limits", ("joints",)),
    "passive": ("tune or check the relaxed-hand (passive sag) model", ("passive",)),
    "play": ("play a take onto the servos (--bus PORT|sim) or to a VMC receiver", ("play",)),
    "record": ("takes: record a glove take, repair a take cut short, convert", ("record",)),
    "retarget": ("robot-hand retarget tables: human curves -> robot joints", ("retarget",)),
    "run": ("run the live rig: glove -> full hands with sag -> servos", ("run",)),
    "sag": ("look up the passive-sag pose at a forearm orientation", ("sag",)),
    "servos": ("servo bring-up: scan, set-id, set-baud, reboot, check", ("servos",)),
    "setup": ("from a plugged-in servo adapter to a working rig file: find the port, write "
              "it, give new servos their IDs and baud", ("setup",)),
    "sim-bus": ("serve emulated Dynamixel X-series servos on a pty (MuJoCo hand loopback)",
                ("sim_bus",)),
    "sim-glove": ("an emulated glove on a pty: stream a recording, or perform the calibration "
                  "poses (prints 'port: PATH' first)", ("sim_glove",)),
}
"""Every subcommand in the order ``--help`` lists it (the modules' order), with its
help line and the modules that register it; tests/handrig/cli/test_cli_startup.py
checks this against what the modules register."""


def command_modules() -> list[str]:
    """The subcommand modules of this package, in order (``_`` helpers left out)."""
    return sorted(info.name for info in pkgutil.iter_modules(__path__)
                  if not info.name.startswith("_"))


def build_parser(command: str | None = None, *, full: bool = True) -> argparse.ArgumentParser:
    """The ``handrig`` parser. ``full``: every command's own parser (every module
    imported); else only ``command``'s (None or unknown: none), the others stand in
    as their name and help line from :data:`COMMANDS`, so ``--help`` and argparse's
    errors read the same."""
    parser = argparse.ArgumentParser(
        prog="handrig",
        description="Realtime hand driver: glove -> two full hands with sag -> servos or sim.",
    )
    parser.add_argument("--version", action="version", version=f"handrig {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    if full:
        for name in command_modules():
            importlib.import_module(f"{__name__}.{name}").register(sub)
        return parser
    for name, (help_line, modules) in COMMANDS.items():
        if name != command:
            sub.add_parser(name, help=help_line)
            continue
        for module in modules:
            importlib.import_module(f"{__name__}.{module}").register(sub)
    return parser


def command_in(argv: Sequence[str]) -> str | None:
    """The subcommand ``argv`` names, if any: its first word that is not an option (the
    top-level parser takes no option with a value)."""
    for arg in argv:
        if arg == "--":
            continue
        if not arg.startswith("-"):
            return arg if arg in COMMANDS else None
    return None


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line (``argv``: default ``sys.argv[1:]``); returns the exit status.

    Called as the program (no ``argv``), the heap is frozen on the way out: the
    interpreter's last collection at exit would walk every object numba, MuJoCo and
    numpy left (most of a second, measured with a ``run``), after the run has ended
    and said so; the process would linger. A wedged adapter must end the run within a
    second, counted to the process's exit."""
    try:
        return _main(argv)
    finally:
        if argv is None:
            gc.freeze()


def _main(argv: Sequence[str] | None) -> int:
    apply_cpus_from_env()  # an emulator started by the rig stays off the loop's CPU
    words = list(sys.argv[1:] if argv is None else argv)
    command = command_in(words)
    parser = build_parser(command, full=False)
    try:
        args = parser.parse_args(words)
        if args.command is not None and args.command != command:
            # argparse took another word for the command than command_in did: parse
            # again with every command's own parser (the answer is then the full one's)
            parser = build_parser()
            args = parser.parse_args(words)
    except SystemExit as exc:  # argparse has printed the usage, or the help
        return exc.code if isinstance(exc.code, int) else 2
    if not getattr(args, "func", None):
        parser.print_help()
        return 0 if args.command is None else 2
    try:
        status = args.func(args)
    except HandrigError as exc:
        print(f"handrig: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("handrig: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `handrig joints | head`: the reader left, not an error
        import os

        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    return int(status or 0)

