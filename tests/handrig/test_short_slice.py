"""A timing thread that cannot have SCHED_FIFO asks the fair scheduler for a short
slice (``handrig.realtime.short_slice``): set through ``sched_setattr``, read back
through ``sched_getattr``, and given back after. Each check runs in a thread of its
own (the setting is per thread), so the test process keeps its own."""

from __future__ import annotations

import os
import platform
import re
import sys
import threading
from collections.abc import Callable

import pytest

from handrig.realtime import SHORT_SLICE_NS, fair_slice_ns, realtime_priority, short_slice


def _in_thread(body: Callable[[], object]) -> object:
    out: list[object] = []
    t = threading.Thread(target=lambda: out.append(body()))
    t.start()
    t.join(10.0)
    return out[0]


def _slices() -> tuple[int | None, bool, int | None, int | None]:
    before = fair_slice_ns()
    with short_slice() as took:
        inside = fair_slice_ns()
    return before, took, inside, fair_slice_ns()


def _kernel_takes_it() -> bool:
    """Linux 6.12 or later on x86_64 or aarch64: the slice is a thread's own."""
    if sys.platform != "linux" or platform.machine() not in ("x86_64", "aarch64"):
        return False
    major, minor = (int(x) for x in re.findall(r"\d+", platform.release())[:2])
    return (major, minor) >= (6, 12)


def test_a_short_slice_is_set_read_back_and_given_back() -> None:
    before, took, inside, after = _in_thread(_slices)  # type: ignore[misc]
    if not _kernel_takes_it():
        pytest.skip("this kernel has no per-thread fair slice (Linux 6.12+, x86_64/aarch64)")
    assert before is not None and took
    assert inside == SHORT_SLICE_NS and SHORT_SLICE_NS == 100_000
    assert after == before != SHORT_SLICE_NS


def _fifo_thread() -> tuple[int | None, int]:
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
    except OSError:
        return -1, -1  # not allowed here
    out = fair_slice_ns(SHORT_SLICE_NS)
    return out, os.sched_getscheduler(0)


def test_a_thread_not_under_the_fair_scheduler_is_left_alone() -> None:
    out, policy = _in_thread(_fifo_thread)  # type: ignore[misc]
    if policy == -1:
        pytest.skip("SCHED_FIFO is not allowed here (not root)")
    assert out is None and policy == os.SCHED_FIFO


def _refused() -> tuple[bool, int | None, list[str]]:
    said: list[str] = []
    # priority 100 is out of SCHED_FIFO's 1..99: refused as no root would be
    with realtime_priority(100, said.append, short_slice_instead=True) as granted:
        inside = fair_slice_ns()
    return granted, inside, said


def test_where_realtime_priority_is_refused_the_loop_runs_with_a_short_slice() -> None:
    if _in_thread(fair_slice_ns) is None:
        pytest.skip("no sched_getattr here")
    granted, inside, said = _in_thread(_refused)  # type: ignore[misc]
    assert not granted and len(said) == 1
    assert said[0].startswith("realtime priority unavailable")
    if _kernel_takes_it():
        assert inside == SHORT_SLICE_NS and "0.1 ms slice" in said[0]
    else:  # a kernel that ignores the request is not said to have granted it
        assert "slice" not in said[0]


def _refused_plain() -> tuple[int | None, list[str]]:
    said: list[str] = []
    with realtime_priority(100, said.append):  # not a loop: no short slice
        inside = fair_slice_ns()
    return inside, said


def test_other_callers_keep_their_slice_where_realtime_priority_is_refused() -> None:
    before = _in_thread(fair_slice_ns)
    inside, said = _in_thread(_refused_plain)  # type: ignore[misc]
    assert inside == before and "slice" not in said[0]
