"""Benches of a base commit and of the working tree, side by side in one run.

``python -m bench.compare --base COMMIT [--benches expand,sag,bus,rig] [--rounds N]
[--seconds S]`` checks ``COMMIT`` out into a temporary git worktree, then runs each
named bench (``python -m bench NAME``) on the base and on this working tree
alternately, ``N`` rounds (the side that goes first alternates too), each run in a
fresh interpreter with the same Python and ``PYTHONPATH`` set to that side's tree (no
second venv: the base runs on this venv's packages). ``--seconds`` is passed to the
benches that take a length (``HANDRIG_BENCH_SECONDS``); other ``HANDRIG_BENCH_*``
settings pass through from the environment. ``--warm-up`` runs each bench once on
each side before the rounds and drops that output (the base worktree starts with no
numba cache, so its first run compiles).

It prints each bench's output once, every number as ``base->new`` (each the median
over the rounds, or with ``--each`` every round's, comma separated; one value where
both sides gave the same in every round). A line whose words differ between the two
sides (a bench that changed what it prints) is printed twice, marked ``base:`` and
``new:`` (the spaces padding a table's columns do not count). The machine is shared and noisy:
read the pairs, not the digits, and run an A/A comparison (``--base HEAD`` on a
clean tree) to see the noise.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
DEFAULT_BENCHES = "expand,sag,bus,rig"


def skeleton(line: str) -> tuple[str, list[str]]:
    """The line with its numbers cut out, and the numbers (as printed)."""
    return NUMBER.sub("\0", line), NUMBER.findall(line)


def _words(line: str) -> str:
    """What two lines must share to be merged: the words, whatever the numbers and
    the spaces padding a table's columns."""
    return " ".join(skeleton(line)[0].split())


def _fmt(values: Sequence[str], each: bool = False) -> str:
    """The median of one number's values over the rounds, printed as the bench did
    (``each``: every round's value, comma separated)."""
    if len(set(values)) == 1:
        return values[0]
    if each:
        return ",".join(values)
    decimals = max((len(v.split(".")[1]) if "." in v and "e" not in v.lower() else 0)
                   for v in values)
    m = statistics.median(float(v) for v in values)
    return f"{m:.{decimals}f}"


def merge(base: list[str], new: list[str], each: bool = False) -> list[str]:
    """One bench's output, ``base`` and ``new`` each a list of rounds' outputs (text):
    line by line, numbers as ``base->new`` where the lines' words agree (laid out as
    the first round of the base printed it)."""
    b_lines = [out.splitlines() for out in base]
    n_lines = [out.splitlines() for out in new]
    length = max(len(x) for x in b_lines + n_lines)
    merged = []
    for i in range(length):
        b_row = [lines[i] for lines in b_lines if i < len(lines)]
        n_row = [lines[i] for lines in n_lines if i < len(lines)]
        shapes = {_words(x) for x in b_row + n_row}
        counts = {len(skeleton(x)[1]) for x in b_row + n_row}
        if len(shapes) != 1 or len(counts) != 1 or not b_row or not n_row:
            merged += [f"base: {x}" for x in b_row[:1]] + [f"new:  {x}" for x in n_row[:1]]
            continue
        shape = skeleton(b_row[0])[0]
        b_nums = [skeleton(x)[1] for x in b_row]
        n_nums = [skeleton(x)[1] for x in n_row]
        parts = []
        for k in range(counts.pop()):
            old = [nums[k] for nums in b_nums]
            now = [nums[k] for nums in n_nums]
            parts.append(_fmt(old) if set(old) == set(now) and len(set(old)) == 1
                         else f"{_fmt(old, each)}->{_fmt(now, each)}")
        pieces = shape.split("\0")
        merged.append("".join(p + (parts[j] if j < len(parts) else "")
                              for j, p in enumerate(pieces)))
    return merged


def run_bench(root: Path, name: str, seconds: float | None) -> str:
    """``python -m bench NAME`` on the code in ``root``; its stdout (stderr appended
    when it failed)."""
    env = dict(os.environ, PYTHONPATH=str(root))
    if seconds is not None:
        env["HANDRIG_BENCH_SECONDS"] = f"{seconds:g}"
    out = subprocess.run([sys.executable, "-m", "bench", name], cwd=root, env=env,
                         capture_output=True, text=True)
    if out.returncode != 0:
        return out.stdout + f"\nFAILED (exit {out.returncode}):\n" + out.stderr[-3000:]
    return out.stdout


def check_imports(root: Path) -> None:
    """Fail unless ``handrig`` and ``bench`` import from ``root`` with its PYTHONPATH."""
    code = "import bench, handrig; print(bench.__file__); print(handrig.__file__)"
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True,
                         text=True, env=dict(os.environ, PYTHONPATH=str(root)))
    files = out.stdout.split()
    if out.returncode != 0 or len(files) != 2 or not all(
            Path(f).resolve().is_relative_to(root.resolve()) for f in files):
        raise SystemExit(f"in {root}, bench and handrig did not import from it: "
                         f"{out.stdout.strip()} {out.stderr[-1000:]}")


def resolve_commit(ref: str) -> str:
    """The full hash of ``ref`` in this repository; SystemExit naming it when it is none."""
    rev = subprocess.run(["git", "rev-parse", "--verify", f"{ref}^{{commit}}"],
                         cwd=HERE, capture_output=True, text=True)
    if rev.returncode != 0:
        raise SystemExit(f"--base {ref!r} is not a commit here: {rev.stderr.strip()}")
    return rev.stdout.strip()


@contextlib.contextmanager
def base_worktree(sha: str, prefix: str = "bench_compare_") -> Iterator[Path]:
    """Commit ``sha`` checked out in a temporary git worktree (removed on exit), whose
    ``handrig`` and ``bench`` import from it (:func:`check_imports`)."""
    with tempfile.TemporaryDirectory(prefix=prefix) as tmp:
        base_root = Path(tmp) / "base"
        subprocess.run(["git", "worktree", "add", "--detach", str(base_root), sha],
                       cwd=HERE, check=True, capture_output=True)
        try:
            check_imports(base_root)
            yield base_root
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(base_root)],
                           cwd=HERE, capture_output=True)


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m bench.compare",
                                description=__doc__.split("\n")[0])
    p.add_argument("--base", required=True, help="the commit to compare against")
    p.add_argument("--benches", default=DEFAULT_BENCHES,
                   help=f"bench names, comma separated (default {DEFAULT_BENCHES})")
    p.add_argument("--rounds", type=int, default=2, help="runs of each side (default 2)")
    p.add_argument("--seconds", type=float, default=None,
                   help="HANDRIG_BENCH_SECONDS for the benches that read it")
    p.add_argument("--each", action="store_true",
                   help="every round's value instead of the median")
    p.add_argument("--warm-up", action="store_true",
                   help="run each bench once on each side first, output dropped")
    return p.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    if args.rounds < 1:
        raise SystemExit("--rounds must be at least 1")
    benches = [b.strip() for b in args.benches.split(",") if b.strip()]
    sha = resolve_commit(args.base)
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=HERE,
                          capture_output=True, text=True).stdout.strip()
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                           cwd=HERE, capture_output=True, text=True).stdout.strip()
    with base_worktree(sha) as base_root:
        sides = {"base": base_root, "new": HERE}
        check_imports(HERE)
        print(f"base {sha[:9]} (a worktree in {base_root}) against new: this tree "
              f"({head}{', with uncommitted changes' if dirty else ''}); {args.rounds} "
              f"rounds, alternating; numbers are base->new, "
              f"{'every round' if args.each else 'medians over the rounds'}",
              flush=True)
        for name in benches:
            outs: dict[str, list[str]] = {"base": [], "new": []}
            if args.warm_up:
                for root in sides.values():
                    run_bench(root, name, args.seconds)
            for k in range(args.rounds):
                order = ("base", "new") if k % 2 == 0 else ("new", "base")
                for side in order:
                    outs[side].append(run_bench(sides[side], name, args.seconds))
            print(f"== {name} ==")
            print("\n".join(merge(outs["base"], outs["new"], args.each)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
