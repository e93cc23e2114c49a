"""The ``handrig`` command line.

Subcommands are the modules of this package (one per subcommand; names
starting with ``_`` are shared helpers): every module has a
``register(subparsers)`` function that adds its parser and sets ``func`` (a
callable taking the parsed namespace and returning an exit status). Errors
handrig raises on purpose print one line and exit 2; never a traceback.
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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="handrig",
        description="Realtime hand driver: glove -> two full hands with sag -> servos or sim.",
    )
    parser.add_argument("--version", action="version", version=f"handrig {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        module.register(sub)
    return parser


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
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
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

