"""The warm-up (handrig/loop/warm_up.py): when the rehearsal runs, and that the parts'
rehearsals change nothing the loop reads while running the same code as the real step.

Pure computation (no port, no thread): the compute-only lane. The live trigger's
warm-up is checked in ``test_warm_up_live.py``.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from firmware_protocol.glove import GloveFrame, encode_frame
from handrig.app.parts import build_parts
from handrig.clock import MonotonicClock
from handrig.config.rig import LoopConfig
from handrig.devices.glove.serial_glove import SerialGlove
from handrig.devices.servo import DynamixelBus
from handrig.errors import ConfigError
from handrig.loop.warm_up import REHEARSAL_ROOM_S, WarmUp


def test_the_rehearsal_runs_once_per_expected_frame_lead_before_it() -> None:
    calls: list[int] = []
    warm = WarmUp(0.00015)
    assert warm.at(1.0, 2.0) is None  # nothing to rehearse with yet
    warm.rehearse_with(lambda: calls.append(1))
    assert warm.at(math.nan, 2.0) is None  # the glove's period is not known yet
    assert warm.at(1.0, 2.0) == pytest.approx(1.0 - 0.00015)
    assert warm.at(1.0, 0.9) is None  # the wait ends (a floor tick) before it is due
    warm.run(1.0, 1.0 - 0.00015)
    assert calls == [1] and warm.count == 1
    assert warm.at(1.0, 2.0) is None  # once per frame, however often the wait restarts
    assert warm.at(1.005, 2.0) == pytest.approx(1.005 - 0.00015)  # the next frame's


def test_no_rehearsal_when_it_would_delay_the_frame() -> None:
    calls: list[int] = []
    warm = WarmUp(0.00015)
    warm.rehearse_with(lambda: calls.append(1))
    warm.run(1.0, 1.0 - REHEARSAL_ROOM_S / 2)  # the wait began too close to the frame
    assert calls == [] and warm.count == 0
    assert warm.at(1.0, 2.0) is None  # and not later for that frame either


def test_a_lead_of_zero_turns_the_warm_up_off_and_the_rig_file_checks_it() -> None:
    warm = WarmUp(0.0)
    warm.rehearse_with(lambda: None)
    assert warm.at(1.0, 2.0) is None
    with pytest.raises(ValueError, match="warm-up lead"):
        WarmUp(-1e-6)
    assert LoopConfig().warm_up_us > 0.0  # on by default
    LoopConfig(warm_up_us=0.0).check()
    with pytest.raises(ConfigError, match="warm_up_us"):
        LoopConfig(warm_up_us=5000.0).check()


def _stats(glove: SerialGlove) -> object:
    """The glove's counters (less the time since its last frame, which runs on)."""
    return dataclasses.replace(glove.stats(), time_since_last_good_s=0.0)


def _frame(seq: int) -> bytes:
    return encode_frame(GloveFrame(seq, seq * 5000, (100, 2000, 3000, 400, 4000),
                                   (0.0, 0.0, 0.3, 0.95), 0, 0))


def test_the_glove_rehearsal_decodes_its_last_bytes_and_changes_nothing(
        monkeypatch: pytest.MonkeyPatch) -> None:
    glove = SerialGlove("/dev/not-opened", clock=MonotonicClock(), reader="poll")
    glove.rehearse()  # nothing read yet: nothing to rehearse
    for seq in range(5):
        glove.feed(_frame(seq), 1.0 + seq * 0.005)
    newest, stats = glove.peek(), _stats(glove)
    decoded: list[int] = []
    real = SerialGlove._frame_sample
    monkeypatch.setattr(SerialGlove, "_frame_sample", staticmethod(
        lambda fr, now, count: (decoded.append(fr.seq), real(fr, now, count))[1]))
    for _ in range(3):
        glove.rehearse()
    assert decoded == [4, 4, 4]  # the newest frame's bytes, decoded again each time
    assert glove.peek() is newest and _stats(glove) == stats
    assert glove.latest() is newest  # still new: a rehearsal takes no frame
    glove.feed(_frame(5)[:10], 1.03)  # half a frame: nothing to decode, nothing kept
    glove.rehearse()
    glove.feed(_frame(5)[10:], 1.031)
    assert glove.peek() is not None and glove.peek().seq == 5  # the real decoder joined it
    assert glove.stats().errors == 0


def test_an_opengloves_rehearsal_changes_nothing() -> None:
    glove = SerialGlove("/dev/not-opened", fmt="opengloves", clock=MonotonicClock(),
                        reader="poll")
    for k in range(4):
        glove.feed(f"A{1000 + k}B2000C3000D400E500\n".encode(), 1.0 + k * 0.01)
    glove.rehearse()
    glove.feed(b"A1200B20", 1.05)  # a partial line: the rehearsal keeps none of it
    newest, stats = glove.peek(), _stats(glove)
    glove.rehearse()
    assert glove.peek() is newest and _stats(glove) == stats
    glove.feed(b"00C3000D400E500\n", 1.06)
    assert glove.peek() is not None and glove.peek().raw[1] == pytest.approx(2000.0)


@pytest.mark.parametrize("rig", [None, "leap"])
def test_the_pipeline_rehearsal_computes_the_real_step_into_scratch(rig: str | None) -> None:
    pipeline = build_parts(rig).pipeline
    controls = pipeline.control_means_deg.copy()
    for k in range(3):
        pipeline.servo_targets(controls + k, 20.0, 10.0, 0.005)
    targets, raw = pipeline.targets.copy(), pipeline.raw_targets.copy()
    counts = (pipeline.rejected, pipeline.slewed)
    moved = controls + 25.0
    scratch = pipeline.rehearse(moved, 35.0, -20.0)
    np.testing.assert_array_equal(pipeline.targets, targets)
    np.testing.assert_array_equal(pipeline.raw_targets, raw)
    assert (pipeline.rejected, pipeline.slewed) == counts
    np.testing.assert_array_equal(scratch, targets)  # no step allowed: held where sent
    rehearsed_raw = pipeline._rehearsal[2].copy()
    pipeline.servo_targets(moved, 35.0, -20.0, 0.005)
    np.testing.assert_allclose(rehearsed_raw, pipeline.raw_targets)  # the same math
    assert not np.allclose(rehearsed_raw, raw)  # and it did move
    pipeline.rehearse(moved, math.nan, 0.0)  # what the real step refuses: no error here


def test_the_bus_rehearsal_builds_the_real_packet_and_sends_nothing() -> None:
    rig = build_parts().rig_config
    bus = DynamixelBus("/dev/not-opened", rig)  # never connected: a send would raise
    writer = bus.writer
    n = len(rig.servos)
    goals = np.linspace(-30.0, 60.0, n)
    goals[2] = np.nan  # held at the last goal: the kernel reads the goals last sent
    goals[3] = 1e6  # clamped
    before = (writer.packet.copy(), bus.last_goals_deg.copy(), bus.stats.copy())
    bus.rehearse_write(goals)
    np.testing.assert_array_equal(writer.packet, before[0])
    np.testing.assert_array_equal(bus.last_goals_deg, before[1])
    assert bus.stats.summary() == before[2].summary()  # no write, no clamp counted
    rehearsed = writer._scratch_packet.copy()
    writer.build(goals)
    np.testing.assert_array_equal(rehearsed, writer.packet)  # byte for byte, CRC too


def test_a_hand_on_a_shared_bus_rehearses_the_whole_bus_write() -> None:
    from handrig.devices.servo.shared import SharedBus

    rig = build_parts().rig_config
    bus = DynamixelBus("/dev/not-opened", rig)
    n = len(rig.servos)
    shared = SharedBus(bus, bus.clock)
    left = shared.part(range(n // 2, n))
    shared.part(range(n // 2))
    goals = np.linspace(10.0, 40.0, n - n // 2)
    packet = bus.writer.packet.copy()
    left.rehearse_write(goals)
    np.testing.assert_array_equal(bus.writer.packet, packet)
    assert np.isnan(bus.last_goals_deg).all()  # nothing sent, nothing remembered
    whole = np.full(n, np.nan)
    whole[n // 2:] = goals  # the other hand's goals: not sent yet (held by the kernel)
    rehearsed = bus.writer._scratch_packet.copy()
    bus.writer.build(whole)
    np.testing.assert_array_equal(rehearsed, bus.writer.packet)
