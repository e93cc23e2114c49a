"""``python -m bench --help`` and each bench's ``--help`` print help and run nothing."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def bench(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "bench", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=60)


def test_help_lists_the_benchmarks_and_runs_none() -> None:
    res = bench("--help")
    assert res.returncode == 0
    assert "usage: python -m bench" in res.stdout and "==" not in res.stdout
    for name in ("rig", "bus", "soak (", "sag"):
        assert f"\n  {name.split(' ')[0]}" in res.stdout
    assert "long: only when named" in res.stdout


def test_a_benchmarks_help_describes_it_without_running_it() -> None:
    rig = bench("rig", "--help")
    assert rig.returncode == 0 and "== bench_rig ==" not in rig.stdout
    assert "HANDRIG_BENCH_SECONDS" in rig.stdout  # its options are variables, described
    soak = bench("soak", "--help")
    assert soak.returncode == 0 and "--seconds" in soak.stdout
    unknown = bench("nope")
    assert unknown.returncode == 2 and "no benchmark 'nope'" in unknown.stderr
