import json
import os
import subprocess
import sys

import pytest

from handrig import realtime
from handrig.realtime import CPUS_ENV, cpu_split, helper_env, pinned_loop, realtime_priority


def test_priority_is_restored_after_the_block():
    before = os.sched_getscheduler(0)
    messages: list[str] = []
    with realtime_priority(10, messages.append) as ok:
        if ok:
            assert os.sched_getscheduler(0) == os.SCHED_FIFO
        else:  # no permission here: it says so instead of failing
            assert messages and "normal priority" in messages[0]
    assert os.sched_getscheduler(0) == before


def test_zero_means_off():
    with realtime_priority(0) as ok:
        assert ok is False


def test_loop_keeps_the_last_cpu_and_helpers_get_the_rest():
    cpus = sorted(os.sched_getaffinity(0))
    loop_cpu, others = cpu_split()
    env = helper_env({})
    if len(cpus) < 2:
        assert loop_cpu is None and CPUS_ENV not in env
        return
    assert loop_cpu == cpus[-1] and others == frozenset(cpus[:-1])
    assert env[CPUS_ENV] == ",".join(str(c) for c in cpus[:-1])
    with pinned_loop(True) as cpu:
        assert cpu == loop_cpu and os.sched_getaffinity(0) == {loop_cpu}
    assert sorted(os.sched_getaffinity(0)) == cpus  # restored
    with pinned_loop(False) as cpu:
        assert cpu is None and sorted(os.sched_getaffinity(0)) == cpus


def test_a_helper_process_stays_off_the_loop_cpu():
    loop_cpu, _ = cpu_split()
    code = ("from handrig.realtime import apply_cpus_from_env; import os; "
            "apply_cpus_from_env(); print(sorted(os.sched_getaffinity(0)))")
    out = subprocess.run([sys.executable, "-c", code], env=helper_env(), capture_output=True,
                         text=True, check=True).stdout
    seen = json.loads(out)
    if loop_cpu is not None:
        assert loop_cpu not in seen and seen
    bad = subprocess.run([sys.executable, "-c", code], env={**os.environ, CPUS_ENV: "x,y"},
                         capture_output=True, text=True, check=True).stdout
    assert json.loads(bad) == sorted(os.sched_getaffinity(0))  # malformed: ignored


def test_pinned_loop_tightens_the_timer_slack_and_restores_it() -> None:
    before = realtime.timer_slack_ns()
    if before is None:
        pytest.skip("no prctl timer slack here")
    with realtime.pinned_loop(enabled=False):
        assert realtime.timer_slack_ns() == realtime.LOOP_TIMER_SLACK_NS
    assert realtime.timer_slack_ns() == before
