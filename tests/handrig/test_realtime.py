import os

from handrig.realtime import realtime_priority


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
