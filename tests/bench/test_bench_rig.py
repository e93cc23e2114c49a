"""The outside latency measurement of ``python -m bench rig``: matching a glove step to
the first Sync Write that moved."""

from __future__ import annotations

import numpy as np
import pytest

from bench.rig_steps import outside_latencies, step_recording


def test_a_step_is_matched_to_the_first_write_that_moved() -> None:
    values = np.array([0.0, 0.0, 1.0, 1.0, 0.0])
    sends = [(1.000, 0), (1.005, 1), (1.010, 2), (1.015, 3), (1.020, 4)]
    writes = [(1.0002, (5, 5)), (1.0052, (5, 5)), (1.0103, (5, 6)), (1.0153, (5, 7)),
              (1.0202, (5, 7)), (1.0251, (5, 6))]
    lat = outside_latencies(sends, values, writes)
    # the step up at 1.010 moved the write at 1.0103; the step down at 1.020 finds the
    # goals still moving (1.0153 != 1.0103) before it, so it is left out
    assert lat == pytest.approx([0.0003])


def test_a_step_is_matched_only_within_the_window() -> None:
    values = np.array([0.0, 1.0])
    sends = [(1.0, 0), (2.0, 1)]
    writes = [(1.9, (1,)), (1.95, (1,)), (2.2, (2,))]
    assert outside_latencies(sends, values, writes) == []


def test_the_step_recording_steps_only_the_index_channel() -> None:
    rec = step_recording()
    changes = np.abs(np.diff(rec.raw, axis=0)).sum(axis=0)
    assert changes[3] > 0 and np.count_nonzero(changes) == 1


@pytest.mark.parametrize("mode", ["fixed", "glove"])
def test_each_case_gets_a_rig_file_that_loads_with_its_mode_rate_and_baud(
        tmp_path, mode: str) -> None:
    from bench.bench_rig import _rig_file
    from handrig.config.rig import load_rig_config

    cfg = load_rig_config(_rig_file(tmp_path, mode, 500.0, 4_000_000))
    assert (cfg.loop.mode, cfg.loop.rate_hz, cfg.bus.baud) == (mode, 500.0, 4_000_000)


def test_the_steal_share_is_the_hypervisors_part_of_all_cpu_time() -> None:
    from bench.rig_steps import cpu_times, steal_percent

    assert steal_percent((1000, 10), (2000, 60)) == 5.0
    assert steal_percent((1000, 10), (1000, 10)) is None
    total, steal = cpu_times()
    assert total >= steal >= 0


def test_cases_are_picked_by_mode_rate_and_baud_or_all_eight() -> None:
    from bench.bench_rig import Case, parse_cases

    assert parse_cases("glove/500/4, fixed/200/1") == [Case("glove", 500.0, 4_000_000),
                                                       Case("fixed", 200.0, 1_000_000)]
    assert len(parse_cases("")) == 8
    with pytest.raises(SystemExit, match="MODE/GLOVE_HZ/MBPS"):
        parse_cases("glove/500")
