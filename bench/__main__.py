"""Run every ``bench/bench_*.py`` module's ``main()`` in turn and print its figures.

``python -m bench NAME ...`` runs only those; the long ones (:data:`LONG`) run only
when named (``python -m bench soak --seconds 60``: the options go to the soak).
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
import time

import bench

# only when named: long, or (bench_view) driving headless chromium pages
LONG = frozenset({"bench_soak", "bench_arrival", "bench_skips", "bench_view"})


def main() -> int:
    modules = pkgutil.iter_modules(bench.__path__)
    names = sorted(m.name for m in modules if m.name.startswith("bench_"))
    only = set(sys.argv[1:])
    for name in names:
        if only and name not in only and name.removeprefix("bench_") not in only:
            continue
        if not only and name in LONG:
            continue
        print(f"== {name} ==", flush=True)
        t0 = time.perf_counter()
        importlib.import_module(f"bench.{name}").main()
        print(f"({name} took {time.perf_counter() - t0:.1f} s)\n", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
