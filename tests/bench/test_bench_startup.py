"""``python -m bench startup``: its first-write case sees a real run's first goal write."""

from __future__ import annotations

from bench.bench_startup import ROOT, to_first_write


def test_first_goal_write_comes_before_the_run_exits() -> None:
    first_s, exit_s = to_first_write(ROOT)
    # the run eases out for 1 s after its one frame: its first goal write is well before
    assert 0.0 < first_s < exit_s - 0.5
