"""A second servo vendor, written to the ServoBus ABC alone, gets the loop's safety for free.

``ToyBus`` implements only the abstract methods of
:class:`~handrig.devices.servo.bus.ServoBus` (no hooks: no wire timing, no housekeeping,
no write stamp, no events of its own) and its own limits. The loop's safety tests run
on it through the real Rig, pipeline, map and sag grid: the [silence] tiers (warn,
hold, relax, stop), the latency stamp, a write every cycle to keep a watchdog fed,
never a goal outside the limits, and torque off on every way out.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import numpy as np
import pytest

from handrig.app.parts import build_parts
from handrig.clock import FakeClock
from handrig.config.rig import SilenceConfig
from handrig.devices.servo.bus import BusStats, ServoBus, ServoState
from handrig.errors import DeviceError, DeviceTimeoutError
from handrig.loop.rig import Rig
from tests.helpers.fakes import ScriptedGlove
from tests.helpers.loop import MID, make_rig, relaxed_targets


class ToyBus(ServoBus):
    """Position servos of another make: goals are clamped into ``[low, high]``; present
    position is the goal last written, except for the servos silenced by the test,
    whose readings go stale and age."""

    def __init__(self, names: tuple[str, ...], low: np.ndarray, high: np.ndarray,
                 clock: FakeClock, write_cost_s: float = 0.0) -> None:
        self._names = names
        self.low, self.high = low, high
        self.clock = clock
        self.write_cost_s = write_cost_s
        self._stats = BusStats(len(names))
        self.connected = False
        self.torque_on = False
        self.torque_offs = 0
        self.goals: list[np.ndarray] = []
        self.asked: list[np.ndarray] = []  # goals as the loop handed them over
        self.write_times: list[float] = []
        self.silent: set[int] = set()
        self._pos = np.zeros(len(names))
        self._heard = np.zeros(len(names))

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self._names

    @property
    def stats(self) -> BusStats:
        return self._stats

    def connect(self) -> None:
        self.connected = True
        self._heard[:] = self.clock.now()

    def close(self) -> None:
        self.torque_on = False
        self.connected = False

    @contextlib.contextmanager
    def torque(self, *, handle_signals: bool = True) -> Iterator[ServoBus]:  # type: ignore[override]
        if not self.connected:
            raise DeviceError("toy bus: not connected")
        self.torque_on = True
        try:
            yield self
        finally:
            self.torque_on = False
            self.torque_offs += 1

    def write_goals_deg(self, goals_deg: np.ndarray) -> int:
        if not self.torque_on:
            raise DeviceError("toy bus: goals with torque off")
        self.asked.append(np.array(goals_deg, dtype=np.float64))  # as the loop sent them
        g = np.clip(np.nan_to_num(goals_deg, nan=0.0), self.low, self.high)
        self.goals.append(g)
        self.write_times.append(self.clock.now())
        self._stats.writes += 1
        self.clock.advance(self.write_cost_s)
        return int(np.count_nonzero(g != goals_deg))

    def read_state(self, deadline_s: float | None = None,
                   part: tuple[int, int] | None = None) -> ServoState:
        now = self.clock.now()
        n = len(self._names)
        self._stats.reads += 1
        stale = np.zeros(n, bool)
        stale[list(self.silent)] = True
        if self.goals:
            self._pos[~stale] = self.goals[-1][~stale]
        self._heard[~stale] = now
        z = np.zeros(n)
        return ServoState(self._pos.copy(), z, z, np.full(n, 35.0), np.zeros(n, np.uint8),
                          np.zeros(n, np.uint8), stale, now - self._heard, now,
                          self._stats.copy())


@pytest.fixture(scope="module")
def parts():
    return build_parts()


def toy(parts, clock: FakeClock, **kw: float) -> ToyBus:
    servos = parts.rig_config.servos
    bus = ToyBus(tuple(s.joint for s in servos), np.array([s.min_deg for s in servos]),
                 np.array([s.max_deg for s in servos]), clock, **kw)
    bus.connect()
    return bus


def rig_on(parts, glove, bus: ToyBus, clock: FakeClock, **kw) -> Rig:
    return make_rig(parts, glove, bus, clock, **kw)


def seeded(bus: ToyBus, parts) -> None:
    """The toy has no last-goals hook: the loop starts from a read of where they are."""
    bus._pos[:] = 0.5 * (parts.pipeline.servo_low + parts.pipeline.servo_high)


def test_the_silence_tiers_warn_hold_relax_and_come_back(parts) -> None:
    clock = FakeClock()
    bus = toy(parts, clock)
    seeded(bus, parts)
    rig = rig_on(parts, ScriptedGlove(clock, lambda t: MID), bus, clock,
                 silence=SilenceConfig(warn_s=0.05, hold_s=0.1, action_s=0.2,
                                       action="relax"))
    held_at: list[float] = []

    def script(t_s: float, pose: np.ndarray) -> None:
        if abs(t_s - 0.5) < 1e-9:
            bus.silent.add(6)
        if abs(t_s - 1.5) < 1e-9:
            bus.silent.clear()
        if 0.7 <= t_s < 1.5:
            held_at.append(float(bus.goals[-1][6]))
    rig.outputs = (script,)
    with bus.torque():
        stats = rig.run(duration_s=2.5)
    events = list(stats.events)
    assert any(e.startswith("no valid reply from servo 7") and "check its cable" in e
               for e in events)
    assert any(e.startswith("holding servo 7") for e in events)
    assert any("relaxing every servo until it answers" in e for e in events)
    assert any(e.startswith("servo 7") and "answers again" in e for e in events)
    assert stats.relax_events == 1 and stats.resumes == 1
    assert stats.servo_silences == 1 and stats.servos_held == 1 and stats.servo_recoveries == 1
    assert len(set(held_at)) == 1  # held at its last goal while silent
    at = bus.goals[int(1.4 * 200)]
    np.testing.assert_allclose(np.delete(at, 6), np.delete(relaxed_targets(parts), 6),
                               atol=1e-6)
    assert not bus.torque_on and bus.torque_offs == 1


def test_the_stop_action_ends_the_run_and_torque_goes_off(parts) -> None:
    clock = FakeClock()
    bus = toy(parts, clock)
    seeded(bus, parts)
    rig = rig_on(parts, ScriptedGlove(clock, lambda t: MID), bus, clock,
                 silence=SilenceConfig(warn_s=0.05, hold_s=0.1, action_s=0.2, action="stop"))
    rig.outputs = (lambda t_s, pose: bus.silent.add(2) if abs(t_s - 0.3) < 1e-9 else None,)
    with pytest.raises(DeviceTimeoutError, match=r"no valid reply from servo 3 .*"
                       r"\[silence\] action is stop"), bus.torque():
        rig.run(duration_s=5.0)
    assert rig.stats.stop_reason.startswith("device error: no valid reply from servo 3")
    assert not bus.torque_on and bus.torque_offs == 1
    assert 0.5 <= clock.now() < 0.7  # at action_s, not at the end of the run


def test_latency_is_stamped_after_the_write_without_a_stamp_from_the_bus(parts) -> None:
    clock = FakeClock(100.0)
    bus = toy(parts, clock, write_cost_s=80e-6)
    seeded(bus, parts)
    rig = rig_on(parts, ScriptedGlove(clock, lambda t: MID), bus, clock)
    with bus.torque():
        stats = rig.run(frames=200)
    assert stats.latency.count >= 200
    assert stats.latency_us(50) == pytest.approx(80.0, abs=1.0)  # the write's cost
    assert rig.telemetry.latest().latency_p50_us == pytest.approx(80.0, abs=1.0)


def test_goals_keep_coming_while_the_glove_is_silent_so_a_watchdog_stays_fed(parts) -> None:
    clock = FakeClock()
    bus = toy(parts, clock)
    seeded(bus, parts)
    glove = ScriptedGlove(clock, lambda t: MID if t < 0.3 or t > 1.5 else None)
    rig = rig_on(parts, glove, bus, clock)
    with bus.torque():
        stats = rig.run(duration_s=2.5)
    gaps = np.diff(bus.write_times)
    assert gaps.max() <= 1.0 / 200.0 + 1e-9  # a write every cycle, frame or not
    assert stats.relax_events == 1 and stats.resumes == 1


def test_never_a_goal_outside_the_limits_and_torque_off_after_an_error(parts) -> None:
    clock = FakeClock()
    bus = toy(parts, clock)
    seeded(bus, parts)
    rng = np.random.default_rng(7)
    wild = lambda t: rng.choice([0.0, 4095.0, 1e9, -1e9, np.nan], size=5)  # noqa: E731
    rig = rig_on(parts, ScriptedGlove(clock, wild), bus, clock)

    def boom(t_s: float, pose: np.ndarray) -> None:
        if t_s >= 1.0:
            raise DeviceError("toy bus: cable pulled")
    rig.outputs = (boom,)
    with pytest.raises(DeviceError, match="cable pulled"), bus.torque():
        rig.run(duration_s=5.0)
    assert not bus.torque_on and bus.torque_offs == 1
    goals = np.array(bus.asked)  # what the loop asked, before the toy bus's own clamp
    low, high = parts.pipeline.servo_low, parts.pipeline.servo_high
    assert len(goals) >= 200 and np.isfinite(goals).all()
    assert (goals >= low - 1e-9).all() and (goals <= high + 1e-9).all()
    assert bus.stats.writes == len(goals)
