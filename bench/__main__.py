"""Run the benchmarks (``bench/bench_*.py``) and print their figures.

``python -m bench`` runs every benchmark but the long ones in turn, printing each
one's figures and how long it took; ``python -m bench NAME ...`` runs only those
(``rig`` or ``bench_rig``); the long ones (soak, arrival, skips) run only when
named, and options after the names go to them (``python -m bench soak --seconds
60``). ``python -m bench --help`` lists them; ``python -m bench NAME --help`` shows
what one measures and its options (most take theirs from HANDRIG_BENCH_* variables,
described there) without running it.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import pkgutil
import sys
import time
from collections.abc import Sequence
from types import ModuleType

import bench

# only when named: long, or (bench_view) driving headless chromium pages, or (bench_rig_hands)
# run by bench_rig already
LONG = frozenset({"bench_soak", "bench_arrival", "bench_skips", "bench_view", "bench_view_exit",
                  "bench_inputs", "bench_one_silent",
                  "bench_wedge", "bench_rig_hands"})
HELP = ("-h", "--help")


def bench_names() -> list[str]:
    return sorted(m.name for m in pkgutil.iter_modules(bench.__path__)
                  if m.name.startswith("bench_"))


def _summary(module_name: str) -> str:
    """The first line of a bench's docstring, read without importing it."""
    import ast
    from pathlib import Path

    source = Path(bench.__path__[0], f"{module_name}.py").read_text(encoding="utf-8")
    doc = ast.get_docstring(ast.parse(source)) or ""
    return doc.strip().splitlines()[0] if doc.strip() else ""


def parser() -> argparse.ArgumentParser:
    lines = []
    for name in bench_names():
        short = name.removeprefix("bench_")
        tag = " (long: only when named)" if name in LONG else ""
        lines.append(f"  {short:<13} {_summary(name)}{tag}")
    p = argparse.ArgumentParser(
        prog="python -m bench", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="benchmarks:\n" + "\n".join(lines))
    p.add_argument("names", nargs="*", metavar="NAME",
                   help="benchmarks to run (default: all but the long ones)")
    return p


def module_help(module: ModuleType, name: str) -> None:
    """``--help`` for one bench: its own parser's, else its docstring."""
    parse = getattr(module, "parse_args", None)
    if callable(parse):
        with contextlib.suppress(SystemExit):  # argparse exits after printing the help
            parse(["--help"])
        return
    print(f"usage: python -m bench {name.removeprefix('bench_')}\n")
    print((module.__doc__ or "").strip())


def main(argv: Sequence[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    names = bench_names()
    wanted: list[str] = []
    rest: list[str] = []
    for i, arg in enumerate(args):
        if arg.startswith("-"):
            rest = args[i:]
            break
        name = arg if arg in names else f"bench_{arg}"
        if name not in names:
            parser().print_usage(sys.stderr)
            print(f"python -m bench: no benchmark {arg!r}; `python -m bench --help` lists them",
                  file=sys.stderr)
            return 2
        wanted.append(name)
    if any(a in HELP for a in rest):
        if not wanted:
            parser().print_help()
            return 0
        for name in wanted:
            module_help(importlib.import_module(f"bench.{name}"), name)
        return 0
    if rest and not any(hasattr(importlib.import_module(f"bench.{n}"), "parse_args")
                        for n in wanted):
        parser().print_usage(sys.stderr)
        print(f"python -m bench: options {' '.join(rest)} are for a benchmark that takes "
              "options (soak)", file=sys.stderr)
        return 2
    sys.argv = [sys.argv[0], *rest]  # a bench with options (soak) reads them from argv
    for name in names:
        if wanted and name not in wanted:
            continue
        if not wanted and name in LONG:
            continue
        print(f"== {name} ==", flush=True)
        t0 = time.perf_counter()
        importlib.import_module(f"bench.{name}").main()
        print(f"({name} took {time.perf_counter() - t0:.1f} s)\n", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
