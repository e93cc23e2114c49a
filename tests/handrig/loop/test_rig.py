"""The realtime loop on a fake clock: rate, safety (silence, e-stop, stop), limits.

The glove and the bus here are fakes that subclass the real ABCs (GloveSource,
ServoBus); the pipeline, map, sag grid and calibration are the real shipped ones.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterator

import numpy as np
import pytest

from handrig.app.parts import build_parts
from handrig.clock import FakeClock
from handrig.config.rig import SilenceConfig
from handrig.devices.glove import GloveSample, GloveSource, GloveStats
from handrig.devices.servo.bus import BusStats, ServoBus, ServoState
from handrig.errors import DeviceError
from handrig.loop.rig import Mode, Rig


class ScriptedGlove(GloveSource):
    """Emits one sample per call while ``raw_at(t)`` returns counts; None = silence."""

    def __init__(self, clock: FakeClock, raw_at: Callable[[float], np.ndarray | None],
                 estop_at: float | None = None) -> None:
        super().__init__()
        self.clock = clock
        self.raw_at = raw_at
        self.estop_at = estop_at
        self.n = 0

    def latest(self) -> GloveSample | None:
        t = self.clock.now()
        raw = self.raw_at(t)
        if raw is None:
            return None
        self.n += 1
        estop = self.estop_at is not None and t >= self.estop_at
        quat = np.array([0.0, 0.0, 0.0, 1.0])  # palm down, forearm horizontal
        return GloveSample(np.asarray(raw, float), quat, int(estop), estop, self.n, 0,
                           t, self.n)

    def stats(self) -> GloveStats:
        return GloveStats(frames_ok=self.n)


class RecordingBus(ServoBus):
    """Remembers every goal vector; present position follows the goal one read late."""

    def __init__(self, names: tuple[str, ...], clock: FakeClock,
                 write_cost_s: float = 0.0, fail_after: int | None = None) -> None:
        self._names = names
        self.clock = clock
        self.write_cost_s = write_cost_s
        self.fail_after = fail_after
        self.goals: list[np.ndarray] = []
        self._stats = BusStats(len(names))
        self.torque_on = False

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self._names

    @property
    def stats(self) -> BusStats:
        return self._stats

    def connect(self) -> None:
        pass

    def close(self) -> None:
        self.torque_on = False

    @contextlib.contextmanager
    def torque(self) -> Iterator[ServoBus]:  # type: ignore[override]
        self.torque_on = True
        try:
            yield self
        finally:
            self.torque_on = False

    def write_goals_deg(self, goals_deg: np.ndarray) -> int:
        if self.fail_after is not None and len(self.goals) >= self.fail_after:
            raise DeviceError("servo port /dev/ttyUSB0 went away (test)")
        self.goals.append(np.array(goals_deg))
        self.clock.advance(self.write_cost_s)
        return 0

    def read_state(self, deadline_s: float | None = None) -> ServoState:
        n = len(self._names)
        pos = self.goals[-1] if self.goals else np.zeros(n)
        z = np.zeros(n)
        return ServoState(pos.copy(), z, z, z, np.zeros(n, np.uint8), np.zeros(n, np.uint8),
                          np.zeros(n, bool), z, self.clock.now(), self._stats.copy())


@pytest.fixture(scope="module")
def parts_factory():
    return lambda: build_parts()


def make_rig(parts, glove, bus, clock, **kw):
    kw.setdefault("loop_mode", "fixed")  # the tests here set the glove-triggered mode
    kw.setdefault("catch_up", False)  # and catching up where they mean it
    return Rig(glove, bus, parts.pipeline, clock, controls_from_raw=parts.controls,
               orientation=parts.orientation, rate_hz=200.0, read_every=4,
               glove_timeout_s=0.25, relax_time_s=0.5, log=lambda s: None, **kw)


MID = np.array([2000.0, 2100.0, 2000.0, 2100.0, 2100.0])


def relaxed_targets(parts, inclination=0.0, rotation=0.0):
    pl = parts.pipeline
    relaxed = np.clip(pl.relaxed_pose(inclination, rotation), pl.pose_low, pl.pose_high)
    return np.clip(relaxed[pl.servo_index], pl.servo_low, pl.servo_high)


def test_loop_holds_its_rate_and_measures_latency(parts_factory):
    parts = parts_factory()
    clock = FakeClock(100.0)
    glove = ScriptedGlove(clock, lambda t: MID)
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock,
                       write_cost_s=50e-6)
    rig = make_rig(parts, glove, bus, clock)
    stats = rig.run(frames=400)
    # 400 cycles following the glove, then relax_time_s (0.5 s) easing to relaxed
    assert stats.frames == len(bus.goals) == 400 + 100 + 1
    assert stats.stop_reason == "400 frames done" and stats.relax_events == 0
    assert stats.rate_hz == pytest.approx(200.0, rel=0.01)
    assert stats.overruns == 0
    assert stats.latency_us(50) == pytest.approx(50.0, abs=1.0)  # the write's cost
    assert stats.reads == 126 and stats.tracking_n > 0
    np.testing.assert_allclose(bus.goals[-1], relaxed_targets(parts), atol=1e-6)


def test_never_a_goal_outside_the_servo_limits(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    rng = np.random.default_rng(1)
    wild = lambda t: rng.choice([0.0, 4095.0, 1e9, -1e9, np.nan], size=5)  # noqa: E731
    glove = ScriptedGlove(clock, wild)
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    make_rig(parts, glove, bus, clock).run(frames=300)
    goals = np.array(bus.goals)
    assert len(goals) > 300
    low = np.array([s.min_deg for s in parts.rig_config.servos])
    high = np.array([s.max_deg for s in parts.rig_config.servos])
    assert np.isfinite(goals).all()
    assert (goals >= low - 1e-9).all() and (goals <= high + 1e-9).all()


def test_glove_silence_eases_to_relaxed_then_resumes(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    fist = np.array([2800.0, 1300.0, 3000.0, 3200.0, 3200.0])
    glove = ScriptedGlove(clock, lambda t: None if 0.5 <= t < 2.0 else fist)
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    events: list[str] = []
    rig = make_rig(parts, glove, bus, clock)
    rig.log = events.append
    rig.run(frames=500)  # 2.5 s, then easing to relaxed
    assert rig.stats.relax_events == 1
    assert any("silent" in e and "relaxed pose" in e for e in events)
    assert any("glove is back" in e for e in events)
    relaxed = parts.pipeline.relaxed_pose(0.0, 0.0)[parts.pipeline.servo_index]
    relaxed = np.clip(relaxed, parts.pipeline.servo_low, parts.pipeline.servo_high)
    at_end_of_silence = bus.goals[int(1.95 * 200)]
    np.testing.assert_allclose(at_end_of_silence, relaxed, atol=1e-6)
    # the fist before the silence is far from relaxed
    assert np.abs(bus.goals[90] - relaxed).max() > 10.0
    # the glove came back at 2.0 s: by 2.4 s the servos follow the fist again
    back = next(i for i, e in enumerate(events) if "glove is back" in e)
    assert back > next(i for i, e in enumerate(events) if "silent" in e)
    assert np.abs(bus.goals[480] - relaxed).max() > 10.0


def test_estop_relaxes_then_ends_the_run(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    glove = ScriptedGlove(clock, lambda t: MID, estop_at=0.3)
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, glove, bus, clock)
    stats = rig.run(frames=10_000)
    assert stats.estop and stats.stop_reason == "e-stop"
    assert 0.3 + 0.5 <= stats.duration_s <= 0.3 + 0.5 + 0.02  # relax_time_s = 0.5
    assert rig.mode is Mode.STOPPING
    relaxed = parts.pipeline.relaxed_pose(0.0, 0.0)[parts.pipeline.servo_index]
    relaxed = np.clip(relaxed, parts.pipeline.servo_low, parts.pipeline.servo_high)
    np.testing.assert_allclose(bus.goals[-1], relaxed, atol=1e-6)


def test_stop_request_relaxes_and_a_second_one_stops_at_once(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    glove = ScriptedGlove(clock, lambda t: MID)
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, glove, bus, clock)
    calls = {"n": 0}

    def stopper(t_s: float, pose: np.ndarray) -> None:
        calls["n"] += 1
        if calls["n"] == 20:
            rig.request_stop("SIGTERM received")
    rig.outputs = (stopper,)
    stats = rig.run(frames=10_000)
    assert stats.stop_reason == "SIGTERM received"
    assert 100 <= stats.frames <= 125  # 20 frames, then 0.5 s of easing at 200 Hz

    clock2 = FakeClock()
    bus2 = RecordingBus(bus.joint_names, clock2)
    rig2 = make_rig(build_parts(), ScriptedGlove(clock2, lambda t: MID), bus2, clock2)
    def twice(t_s: float, pose: np.ndarray) -> None:
        if len(bus2.goals) == 10:
            rig2.request_stop("SIGINT received")
            rig2.request_stop("SIGINT received")
    rig2.outputs = (twice,)
    assert rig2.run(frames=10_000).frames <= 11


def test_overruns_are_counted_with_their_size(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock,
                       write_cost_s=0.012)  # longer than two 5 ms periods
    rig = make_rig(parts, ScriptedGlove(clock, lambda t: MID), bus, clock)
    stats = rig.run(frames=50)
    assert stats.overruns > 0 and stats.missed_cycles >= stats.overruns
    assert stats.overrun_max_s >= 0.005


def test_lost_servo_port_stops_with_the_message(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock, fail_after=30)
    rig = make_rig(parts, ScriptedGlove(clock, lambda t: MID), bus, clock)
    with pytest.raises(DeviceError, match="went away"):
        rig.run(frames=100)
    assert rig.stats.frames == 30 and "went away" in rig.stats.stop_reason


def _silent_glove_rig_held_mid_range(parts):
    """A rig whose glove never sends, its servos seeded at mid-range: (rig, bus, start)."""
    clock = FakeClock()
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    start = 0.5 * (parts.pipeline.servo_low + parts.pipeline.servo_high)
    parts.pipeline.seed(start)
    return make_rig(parts, ScriptedGlove(clock, lambda t: None), bus, clock), bus, start


def test_a_silent_glove_at_start_holds_then_relaxes_from_where_the_servos_are(parts_factory):
    """Never 'all controls 0': before the first frame the servos hold their positions."""
    parts = parts_factory()
    rig, bus, start = _silent_glove_rig_held_mid_range(parts)
    events: list[str] = []
    rig.log = events.append
    rig.run(frames=200)
    held = np.array(bus.goals[: int(0.25 * 200)])
    np.testing.assert_allclose(held, np.broadcast_to(start, held.shape))
    assert any("no glove frame yet" in e for e in events)
    steps = np.abs(np.diff(np.array(bus.goals), axis=0)).max()
    assert steps < 5.0  # eased, never a jump
    np.testing.assert_allclose(bus.goals[-1], relaxed_targets(parts), atol=1e-6)


def test_a_stop_before_the_first_frame_eases_from_the_held_pose(parts_factory):
    parts = parts_factory()
    rig, bus, start = _silent_glove_rig_held_mid_range(parts)
    rig.request_stop("SIGTERM received")  # e.g. during torque-on, before the loop
    rig.run(frames=1000)
    np.testing.assert_allclose(bus.goals[0], start, atol=1e-9)
    assert np.abs(np.diff(np.array(bus.goals), axis=0)).max() < 5.0
    np.testing.assert_allclose(bus.goals[-1], relaxed_targets(parts), atol=1e-6)


def test_the_loop_refuses_to_start_blind(parts_factory):
    parts = parts_factory()
    clock = FakeClock()

    class BlindBus(RecordingBus):
        def read_state(self, deadline_s=None):
            state = super().read_state(deadline_s)
            state.stale[:] = True
            return state

    bus = BlindBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, ScriptedGlove(clock, lambda t: MID), bus, clock)
    with pytest.raises(DeviceError, match="present positions are unknown"):
        rig.run(frames=10)
    assert bus.goals == []


def test_servo_fast_path_equals_the_full_pipeline(parts_factory):
    """servo_targets (precomposed, before the write) == targets of the full pose."""
    parts = parts_factory()
    pl = parts.pipeline
    rng = np.random.default_rng(3)
    means = parts.expander.control_means_deg
    compared = 0
    for _ in range(200):
        c = means + rng.normal(scale=4.0, size=len(means))
        inc, rot = rng.uniform(-89, 89), rng.uniform(-180, 180)
        pose = pl.full_pose(c, inc, rot).copy()
        expanded = parts.expander.expand(c)
        unclamped = parts.expander.map.curve_means_deg + parts.expander.map.gains @ (
            c - parts.expander.map.control_means_deg)
        if not np.allclose(expanded, unclamped):
            continue  # the expander clamped a curve before sag: paths may differ there
        fast = pl.servo_targets(c, inc, rot, 1e6).copy()  # a step the slew limit never holds
        want = np.clip(pose[pl.servo_index], pl.servo_low, pl.servo_high)
        np.testing.assert_allclose(fast, want, atol=1e-9)
        compared += 1
    assert compared >= 50


def test_the_live_control_path_sees_one_sample_per_glove_frame(parts_factory):
    """The live filter sees exactly one sample per glove frame."""
    parts = parts_factory()
    clock = FakeClock()
    seen: list[float] = []

    def controls(raw, t_s, out):
        seen.append(t_s)
        return parts.controls(raw, t_s, out)

    glove = ScriptedGlove(clock, lambda t: MID)
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = Rig(glove, bus, parts.pipeline, clock, controls_from_raw=controls,
              orientation=parts.orientation, rate_hz=200.0, log=lambda s: None,
              loop_mode="fixed")
    stats = rig.run(frames=50)
    assert len(seen) == stats.glove_samples


def test_a_stop_arriving_mid_cycle_never_puts_a_hole_in_the_outputs(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    fist = np.array([2800.0, 1300.0, 3000.0, 3200.0, 3200.0])

    class SignalledBus(RecordingBus):
        rig: Rig | None = None

        def write_goals_deg(self, goals_deg):
            n = super().write_goals_deg(goals_deg)
            if len(self.goals) == 40 and self.rig is not None:
                self.rig.request_stop("SIGINT received")  # a signal between write and outputs
            return n

    bus = SignalledBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    poses: list[np.ndarray] = []
    rig = make_rig(parts, ScriptedGlove(clock, lambda t: fist), bus, clock,
                   outputs=[lambda t, pose: poses.append(pose.copy())])
    bus.rig = rig
    rig.run(frames=1000)
    p = np.array(poses)
    assert len(p) > 100 and not np.any(np.all(p == 0.0, axis=1))
    assert np.abs(np.diff(p, axis=0)).max() < 10.0  # eases, no jump in the stream


def test_after_an_overrun_reads_get_a_deadline_in_the_future(parts_factory):
    parts = parts_factory()
    clock = FakeClock()

    class StallingBus(RecordingBus):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            self.margins: list[float] = []

        def write_goals_deg(self, goals_deg):
            if len(self.goals) == 30:
                self.clock.advance(0.012)  # one write stalls for 12 ms: an overrun
            return super().write_goals_deg(goals_deg)

        def read_state(self, deadline_s=None):
            if deadline_s is not None:  # (the start-up read has none)
                self.margins.append(deadline_s - self.clock.now())
            return super().read_state(deadline_s)

    bus = StallingBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    stats = make_rig(parts, ScriptedGlove(clock, lambda t: MID), bus, clock).run(frames=100)
    assert stats.overruns == 1
    assert min(bus.margins) > 0.001


class SlowGlove(ScriptedGlove):
    """A frame only when a new ``1 / rate_hz`` slot begins (a glove slower than the loop)."""

    def __init__(self, clock: FakeClock, raw_at: Callable[[float], np.ndarray | None],
                 rate_hz: float) -> None:
        super().__init__(clock, raw_at)
        self.rate_hz = rate_hz
        self.slot = -1

    def latest(self) -> GloveSample | None:
        slot = int(self.clock.now() * self.rate_hz + 1e-9)
        if slot == self.slot:
            return None
        self.slot = slot
        return super().latest()


FIST = np.array([2800.0, 1300.0, 3000.0, 3200.0, 3200.0])


def test_a_1_hz_glove_does_not_make_the_puppet_twitch(parts_factory):
    """Each frame of a 1 Hz glove is alone (no run of good frames): after the first loss
    the puppet eases to relaxed and stays there, never pulled back for one frame."""
    parts = parts_factory()
    clock = FakeClock()
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, SlowGlove(clock, lambda t: FIST, 1.0), bus, clock)
    stats = rig.run(duration_s=6.0)
    goals = np.array(bus.goals)
    relaxed = relaxed_targets(parts)
    gap = np.abs(goals[int(0.25 * 200)] - relaxed).max()
    steps = np.abs(np.diff(goals[int(0.25 * 200):], axis=0)).max()
    assert steps <= 1.5 * gap / 0.5 * 0.005 + 1e-6  # a smoothstep over relax_time_s, no jump
    np.testing.assert_allclose(goals[int(1.0 * 200):int(6.0 * 200)],
                               np.broadcast_to(relaxed, goals[200:1200].shape), atol=1e-6)
    assert stats.relax_events == 1 and stats.resumes == 0


def test_resuming_needs_good_frames_in_a_row_then_eases_back(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    glove = ScriptedGlove(clock, lambda t: None if 0.5 <= t < 2.0 else FIST)
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    events: list[str] = []
    rig = make_rig(parts, glove, bus, clock, resume_frames=3, resume_time_s=0.3)
    rig.log = events.append
    stats = rig.run(frames=600)
    goals = np.array(bus.goals)
    relaxed = relaxed_targets(parts)
    back = int(2.0 * 200)
    # the first two frames back do not move the servos: relaxed still
    np.testing.assert_allclose(goals[back:back + 2], np.broadcast_to(relaxed, (2, len(relaxed))),
                               atol=1e-6)
    # then eased: no step bigger than a smoothstep over 0.3 s allows, nowhere near the
    # slew limit's 3.6 deg per 5 ms cycle
    gap = np.abs(goals[int(0.45 * 200)] - relaxed).max()
    steps = np.abs(np.diff(goals[back:back + 100], axis=0)).max()
    assert steps <= 1.5 * gap / 0.3 * 0.005 + 1e-6 and steps < 3.6
    # and following the fist again once the easing is over
    np.testing.assert_allclose(goals[back + 2 + 62], goals[int(0.45 * 200)], atol=0.5)
    assert stats.relax_events == 1 and stats.resumes == 1
    assert any("glove is back" in e and "easing in over 0.30 s" in e for e in events)


def test_resume_frames_1_follows_the_first_frame_back(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    glove = ScriptedGlove(clock, lambda t: None if 0.5 <= t < 2.0 else FIST)
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, glove, bus, clock, resume_frames=1)
    rig.run(frames=500)
    goals = np.array(bus.goals)
    back = int(2.0 * 200)
    assert np.abs(goals[back + 1] - goals[back]).max() > 0.0  # moving from the first frame


def test_the_trigger_is_a_part_that_can_be_swapped(parts_factory):
    """A trigger other than the fixed-rate one drives the same loop."""
    from handrig.loop.trigger import Tick, Trigger

    class EveryOtherSlot(Trigger):
        def __init__(self, clock: FakeClock) -> None:
            self.clock, self.period_s, self.waits, self.k = clock, 0.01, 0, 0

        def start(self, t0_s: float) -> None:
            self.t0 = t0_s

        def wait(self, tick: Tick, *, settle: bool = True) -> Tick:
            self.waits += 1
            deadline = self.t0 + self.k * self.period_s
            self.clock.sleep_until(deadline)
            tick.index, tick.deadline_s, tick.now_s = self.k, deadline, self.clock.now()
            tick.next_s, tick.late_s, tick.skipped = deadline + self.period_s, 0.0, 0
            self.k += 1
            return tick

    parts = parts_factory()
    clock = FakeClock()
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    trigger = EveryOtherSlot(clock)
    rig = make_rig(parts, ScriptedGlove(clock, lambda t: MID), bus, clock, trigger=trigger)
    stats = rig.run(frames=100)
    assert trigger.waits == stats.frames == len(bus.goals)
    assert stats.rate_hz == pytest.approx(100.0, rel=0.02)


def test_a_long_run_keeps_its_statistics_fixed_size(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock,
                       write_cost_s=40e-6)
    bus.goals = _Last()  # type: ignore[assignment]  # the fake bus itself must not grow
    rig = make_rig(parts, ScriptedGlove(clock, lambda t: MID), bus, clock)
    stats = rig.run(frames=6000)
    assert stats.latency.count == stats.glove_samples >= 6000
    assert len(stats.latencies_s) == stats.latencies_s.size < 6000
    assert stats.period.count == stats.frames - 1
    assert not any(isinstance(v, list) for v in vars(stats).values())


class _Last(list):
    """Keeps only the newest goal vector."""

    def append(self, item):  # type: ignore[override]
        self[:] = [item]


def test_the_profile_times_each_stage_outside_the_loop_code(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock,
                       write_cost_s=70e-6)
    rig = make_rig(parts, ScriptedGlove(clock, lambda t: MID), bus, clock, profile=True)
    stats = rig.run(frames=100)
    assert rig.stage_profile is not None
    stages = rig.stage_profile.summary_us()
    assert list(stages) == ["read+decode", "calibrate+filter", "orientation", "targets",
                            "write"]
    assert stages["write"]["p50"] == pytest.approx(70.0, rel=0.02)
    assert stats.latency_us(50) == pytest.approx(70.0, abs=1.0)  # the profile adds nothing


class EventfulGlove(ScriptedGlove):
    """Says once that its port went away and came back."""

    def __init__(self, clock: FakeClock, raw_at: Callable[[float], np.ndarray | None]) -> None:
        super().__init__(clock, raw_at)
        self.pending = ["glove port /dev/ttyACM0 went away", "glove port /dev/ttyACM0 is back"]

    def drain_events(self) -> list[str]:
        out, self.pending = self.pending, []
        return out


class SilentServosBus(RecordingBus):
    """Servo 7 gives no valid reading between two times (the bus reports it stale, with
    the age of its last reading); the loop's [silence] tiers decide what that means."""

    def __init__(self, names: tuple[str, ...], clock: FakeClock, silent: tuple[float, float]
                 ) -> None:
        super().__init__(names, clock)
        self.silent = silent
        self.last_heard = 0.0

    def read_state(self, deadline_s: float | None = None) -> ServoState:
        state = super().read_state(deadline_s)
        t = self.clock.now()
        if self.silent[0] <= t < self.silent[1]:
            state.stale[6] = True
            state.age_s[6] = t - self.last_heard
        else:
            self.last_heard = t
        return state


def test_bus_and_glove_events_reach_the_run_and_a_relax_request_relaxes(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    glove = EventfulGlove(clock, lambda t: MID)
    names = tuple(s.joint for s in parts.rig_config.servos)
    bus = SilentServosBus(names, clock, (0.45, 1.5))
    rig = make_rig(parts, glove, bus, clock, silence=SilenceConfig(
        warn_s=0.01, hold_s=0.02, action_s=0.05, action="relax"))
    rig.run(frames=500)
    events = list(rig.stats.events)
    assert events[:2] == ["glove port /dev/ttyACM0 went away", "glove port /dev/ttyACM0 is back"]
    assert any(e.startswith("holding servo 7") for e in events)
    assert any(e.startswith("no valid reply from servo 7") and "relaxed pose" in e
               for e in events)
    assert any("servos answer again" in e for e in events)
    assert rig.stats.relax_events == 1 and rig.stats.resumes == 1
    relaxed = relaxed_targets(parts)
    # every other servo relaxed; the silent one held at its last goal all along
    at = bus.goals[int(1.45 * 200)]
    np.testing.assert_allclose(np.delete(at, 6), np.delete(relaxed, 6), atol=1e-6)
    assert at[6] == bus.goals[int(0.6 * 200)][6] == bus.goals[int(1.0 * 200)][6]
    assert np.abs(bus.goals[480] - relaxed).max() > 1.0


def test_keys_from_another_thread_relax_resume_and_e_stop_without_easing(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    glove = ScriptedGlove(clock, lambda t: MID)
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, glove, bus, clock)
    modes: list[Mode] = []

    def keys(t_s: float, pose: np.ndarray) -> None:
        n = len(bus.goals)
        modes.append(rig.mode)
        key = {20: rig.toggle_relax, 300: rig.toggle_relax, 400: rig.estop}.get(n)
        if key is not None:  # pressed on the key thread, acted on by the loop
            thread = threading.Thread(target=key)
            thread.start()
            thread.join()
    rig.outputs = (keys,)
    stats = rig.run(frames=10_000)
    assert Mode.RELAXING in modes[20:300] and modes[299] is Mode.RELAXING
    np.testing.assert_allclose(bus.goals[299], relaxed_targets(parts), atol=1e-6)
    assert Mode.RESUMING in modes[300:400] and modes[-2] is Mode.RUNNING
    assert stats.estop and stats.stop_reason == "e-stop key" and stats.resumes == 1
    assert stats.relax_events == 0
    assert stats.frames <= 402  # ended within a cycle or two: no easing


def test_housekeeping_runs_midway_between_state_reads_with_a_deadline(parts_factory):
    parts = parts_factory()
    clock = FakeClock()

    class KeepingBus(RecordingBus):
        def __init__(self, *args):
            super().__init__(*args)
            self.calls: list[tuple[int, float, float]] = []  # (writes so far, now, deadline)

        def housekeeping(self, deadline_s: float) -> bool:
            self.calls.append((len(self.goals), self.clock.now(), deadline_s))
            return True

    bus = KeepingBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, ScriptedGlove(clock, lambda t: MID), bus, clock)  # read_every 4
    rig.run(frames=40)
    writes = [w for w, _, _ in bus.calls]
    assert writes[:3] == [3, 7, 11]  # cycles 2, 6, 10: between the reads of 0, 4, 8
    assert all(now < deadline < now + 0.005 for _, now, deadline in bus.calls)


def _replay(rate_hz: float, seconds: float, clock: FakeClock, gap: tuple[float, float] | None
            = None):
    from handrig.devices.glove import ReplayGlove
    from handrig.devices.glove_recording import GloveRecording

    t = np.arange(int(seconds * rate_hz)) / rate_hz
    if gap is not None:
        t = t[(t < gap[0]) | (t >= gap[1])]
    rec = GloveRecording(t_s=t, raw=np.tile(MID, (len(t), 1)),
                         buttons=np.zeros(len(t), dtype=np.int64),
                         channel_names=tuple(f"c{k}" for k in range(5)),
                         quat_xyzw=np.tile([0.0, 0.0, 0.0, 1.0], (len(t), 1)), rate_hz=rate_hz)
    return ReplayGlove(rec, clock)


@pytest.mark.parametrize("rate_hz", [50.0, 200.0, 500.0])
def test_the_glove_triggered_loop_writes_each_frame_once_as_it_comes(parts_factory, rate_hz):
    parts = parts_factory()
    clock = FakeClock(100.0)
    glove = _replay(rate_hz, 2.0, clock)
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock,
                       write_cost_s=50e-6)
    rig = make_rig(parts, glove, bus, clock, loop_mode="glove", floor_hz=40.0,
                   ceiling_hz=1000.0)
    stats = rig.run(duration_s=1.0)
    assert stats.loop_mode == "glove"
    assert stats.frames_skipped == 0 and stats.overruns == 0
    assert stats.glove_samples == pytest.approx(rate_hz * 1.5, abs=3)  # run, then stop easing
    assert stats.latency_us(50) == pytest.approx(50.0, abs=1.0)  # arrival to write: its cost
    assert stats.compute_us(50) == pytest.approx(50.0, abs=1.0)
    assert stats.reads > 0 and stats.relax_events == 0
    np.testing.assert_allclose(bus.goals[-1], relaxed_targets(parts), atol=1e-6)


def test_the_glove_triggered_loop_keeps_the_floor_and_relaxes_and_resumes(parts_factory):
    parts = parts_factory()
    clock = FakeClock(0.0)
    glove = _replay(200.0, 3.0, clock, gap=(0.5, 1.5))  # a second of silence
    bus = RecordingBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, glove, bus, clock, loop_mode="glove", floor_hz=100.0,
                   ceiling_hz=1000.0)
    stats = rig.run(duration_s=2.5)
    assert stats.relax_events == 1 and stats.resumes == 1
    assert stats.cycles_without_frame == pytest.approx(100, abs=3)  # 1 s at the 100 Hz floor
    assert stats.period.max <= 0.010 + 1e-9  # never quieter than the floor


class WiredBus(RecordingBus):
    """A bus that says its baud rate and a read's wire time (Fast Sync Read, 4 bytes)."""

    baud = 1_000_000

    def read_wire_s(self, n: int) -> float:
        return ((14 + n) + (8 + 8 * n)) * 10 / self.baud


def test_no_gap_read_is_offered_that_the_wire_cannot_carry(parts_factory):
    parts = parts_factory()
    clock = FakeClock(0.0)
    glove = _replay(500.0, 2.0, clock)  # 2 ms gaps: the write and a read need 3.2 ms of wire
    bus = WiredBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, glove, bus, clock, loop_mode="glove", floor_hz=100.0,
                   ceiling_hz=1000.0)
    stats = rig.run(duration_s=1.0)
    # only the forced reads, one per FORCED_READ_FACTOR * read_every cycles
    assert 0 < stats.reads <= stats.frames / 16 + 1



def test_no_gap_read_is_offered_while_the_line_must_go_quiet(parts_factory):
    """After a failed reply the bus must let the line go quiet before its next request
    (DynamixelBus.quiet_wait_s): a read asked into a gap then waits out most of it and
    runs past the next frame. The loop counts that wait: while it is longer than the
    gaps, only the forced reads are asked."""
    parts = parts_factory()
    clock = FakeClock(0.0)
    glove = _replay(200.0, 1.0, clock)

    class QuietingBus(WiredBus):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            self.asked: list[float] = []

        def quiet_wait_s(self) -> float:
            return 0.010 if 0.2 <= self.clock.now() < 0.6 else 0.0

        def read_state(self, deadline_s=None):
            self.asked.append(self.clock.now())
            return super().read_state(deadline_s)

    bus = QuietingBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, glove, bus, clock, loop_mode="glove", floor_hz=100.0,
                   ceiling_hz=1000.0)
    rig.run(duration_s=0.9)
    asked = np.array(bus.asked)
    quiet = np.sum((asked >= 0.2) & (asked < 0.6))  # 80 cycles: 20 gap reads otherwise
    assert 0 < quiet <= 80 / 16 + 1  # one forced read per FORCED_READ_FACTOR * read_every
    assert np.sum(asked < 0.2) >= 40 / 4 - 1  # before: a gap read every read_every cycles


def test_a_read_the_bus_found_no_room_for_stays_due_and_is_not_counted(parts_factory):
    parts = parts_factory()
    clock = FakeClock()

    class CrampedBus(RecordingBus):
        """Skips every read asked with less than 10 ms to go (the way DynamixelBus does
        when the wire or a line it must let go quiet leaves no room)."""

        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            self.asked: list[float] = []

        def read_state(self, deadline_s=None):
            if deadline_s is not None:
                self.asked.append(deadline_s - self.clock.now())
                if deadline_s - self.clock.now() < 0.0075:
                    self._stats.skipped_reads += 1
                    state = super().read_state(deadline_s)
                    state.sent = False  # declined: the loop learns it from the result
                    state.stale[:] = True
                    return state
            return super().read_state(deadline_s)

    bus = CrampedBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    stats = make_rig(parts, ScriptedGlove(clock, lambda t: MID), bus, clock).run(frames=200)
    # the regular reads (5 ms slots) are skipped: they stay due, so the forced read over
    # two slots comes every FORCED_READ_FACTOR * read_every cycles and is the only one
    # counted; a skipped read resetting the count would starve the loop of reads
    assert bus.stats.skipped_reads > 0
    assert stats.reads > 0 and stats.reads == sum(1 for a in bus.asked if a >= 0.0075)


def test_reads_of_parts_take_the_parts_in_turn_and_track_only_the_servos_asked(
        parts_factory):
    parts = parts_factory()
    clock = FakeClock()

    class PartBus(RecordingBus):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            self.parts: list[tuple[int, int]] = []

        def read_state(self, deadline_s=None, part=None):
            state = super().read_state(deadline_s)
            if part is not None:
                self.parts.append(part)
                asked = np.zeros(len(self._names), bool)
                asked[part[0]::part[1]] = True
                state.asked = asked
                state.positions_deg[~asked] += 50.0  # old readings: far from the goals
            return state

    bus = PartBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, ScriptedGlove(clock, lambda t: MID), bus, clock, read_parts=2)
    stats = rig.run(frames=100)
    assert bus.parts[:4] == [(0, 2), (1, 2), (0, 2), (1, 2)]
    assert stats.reads == len(bus.parts) and stats.stale_reads == 0
    assert stats.tracking_max_deg < 50.0  # only the servos each read asked for


def test_a_loop_held_up_writes_the_frames_it_was_late_for_then_the_newest(parts_factory):
    """A real glove on a pty at 100 Hz, each frame's index channel a step further; the bus
    holds the loop up 35 ms once in a while (a slow read, the host): the two frames that
    came before the newest meanwhile are still written, oldest first, filtered a period
    apart, and then the newest at once. Every frame the glove sent is written, in order,
    or counted as lost: on a loaded machine a hold-up can last longer than the sleep
    asked, and a fourth frame then comes before the newest, beyond the ceiling's burst
    (CEILING_BURST: two caught up and the newest); that frame is counted (a host stall,
    or skipped), never lost unsaid."""
    import os
    import time
    import tty

    from firmware_protocol.glove import GloveFrame, encode_frame
    from handrig.clock import MonotonicClock
    from handrig.devices.glove import SerialGlove

    parts = parts_factory()
    clock = MonotonicClock(spin_s=0.0)
    master, slave = os.openpty()
    tty.setraw(master)
    glove = SerialGlove(os.ttyname(slave), "frames", clock=clock, reader="poll", channels=5)
    os.close(slave)

    class HeldUpBus(RecordingBus):
        def write_goals_deg(self, goals_deg: np.ndarray) -> int:
            self.goals.append(np.array(goals_deg))
            if len(self.goals) % 25 == 0:
                time.sleep(0.035)  # three periods and a half: three frames come meanwhile
            return 0

    bus = HeldUpBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    filtered: list[float] = []
    seen: list[int] = []
    controls = parts.controls

    sent = 120

    def controls_from_raw(raw, t_s, out):
        filtered.append(t_s)
        seen.append(int(raw[0]))
        if seen[-1] == 1500 + 5 * (sent - 1):  # the glove's last frame: the run is over
            rig.request_stop("the glove's last frame")
        return controls(raw, t_s, out)

    output_at: list[tuple[float, float]] = []

    def stream() -> None:
        while not bus.goals:  # the loop has begun: nothing is left as a backlog
            time.sleep(0.002)
        t = time.monotonic()
        for k in range(sent):
            t += 0.01
            time.sleep(max(0.0, t - time.monotonic()))
            raw = (1500 + 5 * k, 2100, 2000, 2100, 2100)
            os.write(master, encode_frame(GloveFrame(k, k * 10_000, raw, (0.0, 0.0, 0.0, 1.0))))

    rig = Rig(glove, bus, parts.pipeline, clock, controls_from_raw=controls_from_raw,
              orientation=parts.orientation, read_every=4, glove_timeout_s=0.25,
              relax_time_s=0.05, log=lambda s: None, loop_mode="glove", floor_hz=20.0,
              ceiling_hz=1000.0, catch_up=True,
              outputs=[lambda t_s, pose: output_at.append((t_s, float(pose[0])))])
    with glove:
        writer = threading.Thread(target=stream)
        writer.start()
        try:
            # until the glove's last frame (1.2 s of frames; later on a loaded machine:
            # the frames are all there before the run ends however late they come)
            stats = rig.run(duration_s=30.0)
        finally:
            writer.join()
    os.close(master)
    assert stats.stop_reason == "the glove's last frame"
    assert stats.frames_caught_up >= 8  # each hold-up left two frames behind the newest
    assert rig.trigger.catch_ups == stats.frames_caught_up
    got = [(r - 1500) // 5 for r in seen]
    assert np.all(np.diff(got) > 0) and got[-1] == sent - 1  # each once, in order
    lost = sent - len(got)
    assert stats.glove_samples == len(got)
    # every frame not written is counted, and as what it was (a hold-up that ran long:
    # the host's stall; a shorter one that let a fourth frame in: skipped by the loop)
    assert (stats.frames_skipped + stats.frames_in_host_stalls + stats.frames_in_bursts
            == lost), (sorted(set(range(sent)) - set(got)), stats.frames_skipped,
                       stats.frames_in_host_stalls, stats.frames_in_bursts)
    assert np.all(np.diff(filtered) > 0.0)  # and at times that only move on
    # every cycle's pose reaches the outputs in order, a caught-up frame's after the
    # newest frame's write but before its pose
    assert len(output_at) >= sent  # (cycles waiting for the first frame output none)
    assert np.all(np.diff([t for t, _ in output_at]) > 0.0)


@pytest.mark.parametrize("catch_up", [True, False])
def test_a_replay_the_loop_falls_behind_on_still_has_every_sample_written(parts_factory,
                                                                          catch_up):
    parts = parts_factory()
    clock = FakeClock(100.0)
    glove = _replay(200.0, 2.0, clock)

    class SlowAtTimesBus(RecordingBus):
        def write_goals_deg(self, goals_deg: np.ndarray) -> int:
            self.goals.append(np.array(goals_deg))
            clock.advance(0.012 if len(self.goals) % 40 == 0 else 50e-6)  # 2 samples due
            return 0

    bus = SlowAtTimesBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, glove, bus, clock, loop_mode="glove", floor_hz=40.0,
                   ceiling_hz=1000.0, catch_up=catch_up)
    stats = rig.run(duration_s=1.0)
    if catch_up:
        assert stats.frames_caught_up >= 5 and stats.frames_skipped == 0
        assert glove.stats().frames_lost == 0
    else:
        assert stats.frames_caught_up == 0 and stats.frames_skipped >= 5
    assert stats.overruns == 0
