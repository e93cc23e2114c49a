"""The realtime loop on a fake clock: rate, safety (silence, e-stop, stop), limits, events,
keys. (The glove-triggered loop and its reads: test_rig_glove_triggered.py.)

The glove and the bus here are fakes that subclass the real ABCs (GloveSource,
ServoBus); the pipeline, map, sag grid and calibration are the real shipped ones.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np
import pytest

from handrig.app.parts import build_parts
from handrig.clock import FakeClock
from handrig.config.rig import SilenceConfig
from handrig.devices.glove import GloveSample
from handrig.devices.servo.bus import ServoState
from handrig.errors import DeviceError
from handrig.loop.rig import Mode, Rig
from tests.helpers.fakes import FakeBus, ScriptedGlove
from tests.helpers.loop import MID, make_rig, relaxed_targets, rig_on


@pytest.fixture(scope="module")
def parts_factory():
    return lambda: build_parts()


def test_loop_holds_its_rate_and_measures_latency(parts_factory):
    parts = parts_factory()
    clock = FakeClock(100.0)
    glove = ScriptedGlove(clock, lambda t: MID)
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock,
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
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock)
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
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock)
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
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock)
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
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock)
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
    bus2 = FakeBus(bus.joint_names, clock2)
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
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock,
                       write_cost_s=0.012)  # longer than two 5 ms periods
    rig = make_rig(parts, ScriptedGlove(clock, lambda t: MID), bus, clock)
    stats = rig.run(frames=50)
    assert stats.overruns > 0 and stats.missed_cycles >= stats.overruns
    assert stats.overrun_max_s >= 0.005


def test_lost_servo_port_stops_with_the_message(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock, fail_after=30)
    rig = make_rig(parts, ScriptedGlove(clock, lambda t: MID), bus, clock)
    with pytest.raises(DeviceError, match="went away"):
        rig.run(frames=100)
    assert rig.stats.frames == 30 and "went away" in rig.stats.stop_reason


def _silent_glove_rig_held_mid_range(parts):
    """A rig whose glove never sends, its servos seeded at mid-range: (rig, bus, start)."""
    clock = FakeClock()
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock)
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

    class BlindBus(FakeBus):
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
        gains_f, bias, knots = parts.expander.map.feature_gains()  # hinges included
        unclamped = bias + gains_f @ np.concatenate([c, np.maximum(c - knots, 0.0)])
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
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = rig_on(parts, glove, bus, clock, controls_from_raw=controls, rate_hz=200.0,
                 mode="fixed")
    stats = rig.run(frames=50)
    assert len(seen) == stats.glove_samples


def test_a_stop_arriving_mid_cycle_never_puts_a_hole_in_the_outputs(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    fist = np.array([2800.0, 1300.0, 3000.0, 3200.0, 3200.0])

    class SignalledBus(FakeBus):
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

    class StallingBus(FakeBus):
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
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock)
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
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock)
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
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock)
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
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    trigger = EveryOtherSlot(clock)
    rig = make_rig(parts, ScriptedGlove(clock, lambda t: MID), bus, clock, trigger=trigger)
    stats = rig.run(frames=100)
    assert trigger.waits == stats.frames == len(bus.goals)
    assert stats.rate_hz == pytest.approx(100.0, rel=0.02)


def test_a_long_run_keeps_its_statistics_fixed_size(parts_factory):
    parts = parts_factory()
    clock = FakeClock()
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock,
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
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock,
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


class SilentServosBus(FakeBus):
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
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock)
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

    class KeepingBus(FakeBus):
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
