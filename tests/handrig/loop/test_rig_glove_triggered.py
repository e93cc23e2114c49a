"""The glove-triggered loop on a fake clock (and one on a real pty): a cycle per glove
frame, the floor, the reads it offers in the gaps, catching up on frames a hold-up left
behind. (The fixed-rate loop and the safety behaviour: test_rig.py.)

The glove and the bus here are fakes that subclass the real ABCs (GloveSource,
ServoBus); the pipeline, map, sag grid and calibration are the real shipped ones.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

from handrig.app.parts import build_parts
from handrig.clock import FakeClock
from tests.helpers.fakes import FakeBus, ScriptedGlove
from tests.helpers.loop import MID, make_rig, relaxed_targets, rig_on


@pytest.fixture(scope="module")
def parts_factory():
    return lambda: build_parts()


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
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock,
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
    bus = FakeBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, glove, bus, clock, loop_mode="glove", floor_hz=100.0,
                   ceiling_hz=1000.0)
    stats = rig.run(duration_s=2.5)
    assert stats.relax_events == 1 and stats.resumes == 1
    assert stats.cycles_without_frame == pytest.approx(100, abs=3)  # 1 s at the 100 Hz floor
    assert stats.period.max <= 0.010 + 1e-9  # never quieter than the floor


class WiredBus(FakeBus):
    """A bus that says its baud rate and a read's wire time (Fast Sync Read, 4 bytes),
    and keeps each read's (part, time left to its deadline)."""

    baud = 1_000_000

    def __init__(self, *a, **k):
        super().__init__(*a, **k)
        self.reads: list[tuple[tuple[int, int] | None, float]] = []

    def read_wire_s(self, n: int) -> float:
        return ((14 + n) + (8 + 8 * n)) * 10 / self.baud

    def read_state(self, deadline_s=None, part=None, *, patient=False):
        if deadline_s is not None:  # (the start-up read has none)
            self.reads.append((part, deadline_s - self.clock.now()))
        return super().read_state(deadline_s, part, patient=patient)


def test_no_gap_read_is_offered_that_the_wire_cannot_carry(parts_factory):
    """At 500 Hz the gaps are 2 ms: a read of the 20 servos needs 2.0 ms of wire, so
    the loop first gets only its forced reads (one per FORCED_READ_FACTOR * read_every
    cycles, each delaying a write); the first one is split in two (it asks 10 servos),
    and reads of 10 servos (1.1 ms) then fit the gaps."""
    parts = parts_factory()
    clock = FakeClock(0.0)
    glove = _replay(500.0, 2.0, clock)
    bus = WiredBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, glove, bus, clock, loop_mode="glove", floor_hz=100.0,
                   ceiling_hz=1000.0)
    stats = rig.run(duration_s=1.0)
    forced, halves = bus.reads[0], bus.reads[1:]
    assert forced == ((0, 2), pytest.approx(forced[1])) and forced[1] > 0.002  # split first
    assert stats.read_splits == 1
    assert [e for e in stats.events if "found no room" in e] == [
        "reads of 20 servos found no room between the glove's frames (each one delayed "
        "a write): each read now asks 10 servos, in 2 parts"]
    assert {p for p, _ in halves} == {(0, 2), (1, 2)}
    assert all(left >= bus.read_wire_s(10) for _, left in halves)  # the wire carries them
    assert all(left < 0.002 for _, left in halves)  # in the gaps: no write delayed
    assert len(halves) >= 0.9 * stats.frames / 4  # about every read_every-th gap has one


def test_reads_split_no_further_than_read_parts_max(parts_factory):
    """A wire too slow for even the smallest read: the reads are split to 8 parts (3
    servos each) and then forced as before."""
    parts = parts_factory()
    clock = FakeClock(0.0)
    glove = _replay(500.0, 2.0, clock)

    class SlowBus(WiredBus):
        baud = 100_000

    bus = SlowBus(tuple(s.joint for s in parts.rig_config.servos), clock)
    rig = make_rig(parts, glove, bus, clock, loop_mode="glove", floor_hz=100.0,
                   ceiling_hz=1000.0)
    stats = rig.run(duration_s=1.0)
    assert stats.read_splits == 3  # 1 -> 2 -> 4 -> 8 parts
    assert bus.reads[-1][0] is not None and bus.reads[-1][0][1] == 8
    assert 0 < stats.reads <= stats.frames / 16 + 4


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
    stats = rig.run(duration_s=0.9)
    assert stats.read_splits == 0  # the quiet, not the wire, left no room: no split
    asked = np.array(bus.asked)
    quiet = np.sum((asked >= 0.2) & (asked < 0.6))  # 80 cycles: 20 gap reads otherwise
    assert 0 < quiet <= 80 / 16 + 1  # one forced read per FORCED_READ_FACTOR * read_every
    assert np.sum(asked < 0.2) >= 40 / 4 - 1  # before: a gap read every read_every cycles


def test_a_read_the_bus_found_no_room_for_stays_due_and_is_not_counted(parts_factory):
    parts = parts_factory()
    clock = FakeClock()

    class CrampedBus(FakeBus):
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

    class PartBus(FakeBus):
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

    class HeldUpBus(FakeBus):
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

    rig = rig_on(parts, glove, bus, clock, controls_from_raw=controls_from_raw,
                 read_every=4, glove_timeout_s=0.25, relax_time_s=0.05, mode="glove",
                 floor_hz=20.0, ceiling_hz=1000.0, catch_up=True,
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

    class SlowAtTimesBus(FakeBus):
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
