import pytest

from handrig.clock import Clock, FakeClock, MonotonicClock


def test_fake_clock_jumps_to_deadlines():
    c = FakeClock(10.0)
    assert isinstance(c, Clock)
    c.sleep_until(10.5)
    assert c.now() == 10.5
    c.sleep_until(10.0)  # in the past: no change
    assert c.now() == 10.5
    c.sleep(0.25)
    assert c.now() == 10.75 and c.sleeps == 3
    with pytest.raises(ValueError):
        c.advance(-1)


def test_monotonic_clock_sleeps_until_deadline():
    c = MonotonicClock()
    t0 = c.now()
    c.sleep_until(t0 + 0.002)
    assert c.now() >= t0 + 0.002
