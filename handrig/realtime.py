"""Realtime scheduling for the loop thread, best effort.

With ``SCHED_FIFO`` the loop is not preempted by ordinary processes (an emulator,
a compiler, a browser on the show laptop): on a loaded 2-core machine the loop's
p99 latency fell from about 4 ms to about 0.5 ms. It needs root or
``CAP_SYS_NICE`` (or an rtprio limit); without it the loop runs at normal
priority and says so. Only the calling thread is raised, and only inside the
``with`` block; threads started before keep their priority.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator


@contextlib.contextmanager
def realtime_priority(
    priority: int = 20, log: Callable[[str], None] | None = None
) -> Iterator[bool]:
    """Run the block at SCHED_FIFO ``priority`` (1..99); yields whether it worked."""
    if not hasattr(os, "sched_setscheduler") or priority <= 0:
        yield False
        return
    try:
        old_policy = os.sched_getscheduler(0)
        old_param = os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, OSError) as exc:
        if log is not None:
            log(f"realtime priority unavailable ({exc.strerror or exc}): "
                "the loop runs at normal priority")
        yield False
        return
    try:
        yield True
    finally:
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, old_policy, old_param)
