"""A loop is built from two records: :class:`LoopParts` (what it runs on) and
:class:`RigSettings` (the rig file's numbers); ``Rig.from_config`` reads them from a rig
file and holds the glove-triggered ceiling below what the wire carries. The cycle hands
the telemetry a typed :class:`CycleView`. Nothing here runs a loop."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from handrig.app.parts import build_parts
from handrig.clock import FakeClock
from handrig.config.rig import HeatConfig, SilenceConfig
from handrig.loop.rig import WIRE_SHARE, Rig
from handrig.loop.settings import LoopParts, RigSettings
from handrig.loop.telemetry import CycleView
from handrig.loop.trigger import FixedRateTrigger, GloveTrigger
from tests.helpers.fakes import FakeBus, ScriptedGlove
from tests.helpers.loop import MID


class WiredFakeBus(FakeBus):
    """A bus whose goal Sync Write takes ``write_s`` on the wire."""

    def __init__(self, names: tuple[str, ...], clock: FakeClock, write_s: float) -> None:
        super().__init__(names, clock)
        self.write_s = write_s

    def write_wire_s(self) -> float:
        return self.write_s


@pytest.fixture(scope="module")
def parts():
    return build_parts()


def rig_from(parts, bus: FakeBus, clock: FakeClock, **replace_loop: object) -> Rig:
    config = parts.rig_config
    if replace_loop:
        config = dataclasses.replace(config, loop=dataclasses.replace(config.loop,
                                                                      **replace_loop))
    return Rig.from_config(config, ScriptedGlove(clock, lambda t: MID), bus, parts.pipeline,
                           clock, controls_from_raw=parts.controls,
                           orientation=parts.orientation, log=lambda s: None)


def names(parts) -> tuple[str, ...]:
    return tuple(s.joint for s in parts.rig_config.servos)


def test_from_config_holds_the_ceiling_below_what_the_wire_carries(parts) -> None:
    clock = FakeClock()
    # 2 ms a write: at most 0.9 / 2 ms = 450 writes a second, under the file's 1000
    rig = rig_from(parts, WiredFakeBus(names(parts), clock, 0.002), clock, mode="glove",
                   floor_hz=100.0, ceiling_hz=1000.0)
    assert isinstance(rig.trigger, GloveTrigger)
    assert rig.settings.loop.ceiling_hz == pytest.approx(WIRE_SHARE / 0.002)
    assert rig.trigger.min_gap_s == pytest.approx(0.002 / WIRE_SHARE)
    # never below the floor (a wire slower than the floor rate: the floor wins)
    slow = rig_from(parts, WiredFakeBus(names(parts), clock, 0.05), clock, mode="glove",
                    floor_hz=100.0, ceiling_hz=1000.0)
    assert slow.settings.loop.ceiling_hz == 100.0
    # a bus with no wire (wire time 0): the file's ceiling as it is
    free = rig_from(parts, FakeBus(names(parts), clock), clock, mode="glove",
                    floor_hz=100.0, ceiling_hz=800.0)
    assert free.settings.loop.ceiling_hz == 800.0
    assert free.trigger.period_s == pytest.approx(0.01)  # the floor's period


def test_from_config_carries_the_rig_files_settings_into_the_parts(parts) -> None:
    clock = FakeClock()
    silence = SilenceConfig(warn_s=0.2, hold_s=0.5, action_s=2.0, action="relax")
    heat = HeatConfig(warn_c=50.0, act_c=55.0, action_c=60.0, action="stop")
    config = dataclasses.replace(
        parts.rig_config, silence=silence, heat=heat,
        bus=dataclasses.replace(parts.rig_config.bus, read_every=3, read_parts=2),
        loop=dataclasses.replace(parts.rig_config.loop, mode="fixed", rate_hz=250.0,
                                 glove_timeout_s=0.4, relax_time_s=0.7, resume_frames=5,
                                 resume_time_s=0.2))
    rig = Rig.from_config(config, ScriptedGlove(clock, lambda t: MID),
                          FakeBus(names(parts), clock), parts.pipeline, clock,
                          controls_from_raw=parts.controls, orientation=parts.orientation,
                          log=lambda s: None, profile=True, ease_in=True,
                          raw_channels=[3, 2, 1])
    assert isinstance(rig.trigger, FixedRateTrigger) and rig.period_s == pytest.approx(0.004)
    assert (rig.cycle.read_every, rig.cycle.read_parts) == (3, 2)
    assert rig.cycle.silence.config == silence and rig.cycle.heat.config == heat
    assert rig.machine.glove_timeout_s == 0.4 and rig.machine.resume_frames == 5
    assert rig.cycle.relax.duration_s == 0.7 and rig.cycle.resume.duration_s == 0.2
    assert rig.machine.ease_in and rig.stage_profile is not None
    assert rig.parts.raw_channels == (3, 2, 1)
    assert rig.settings == RigSettings(loop=config.loop, bus=config.bus, silence=silence,
                                       heat=heat, ease_in=True, profile=True)


def test_the_records_are_frozen_and_a_loop_mode_nobody_knows_is_refused(parts) -> None:
    clock = FakeClock()
    loop_parts = LoopParts(ScriptedGlove(clock, lambda t: MID), FakeBus(names(parts), clock),
                           parts.pipeline, clock, controls_from_raw=parts.controls,
                           orientation=parts.orientation)
    settings = RigSettings()
    with pytest.raises(dataclasses.FrozenInstanceError):
        settings.ease_in = True  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        loop_parts.clock = FakeClock()  # type: ignore[misc]
    odd = RigSettings(loop=dataclasses.replace(settings.loop, mode="sometimes"))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="loop mode 'sometimes' unknown"):
        Rig(loop_parts, odd, log=lambda s: None)
    assert Rig(loop_parts, log=lambda s: None).settings == RigSettings()  # the defaults


def test_the_cycle_hands_the_telemetry_a_typed_view(parts) -> None:
    clock = FakeClock()
    bus = FakeBus(names(parts), clock)
    rig = rig_from(parts, bus, clock, mode="fixed")
    before = rig.cycle.view()
    assert isinstance(before, CycleView)
    assert before.raw is None and before.pose is None and before.state is None
    assert math.isnan(before.frame_s) and before.angles_deg == (0.0, 0.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        before.frame_s = 0.0  # type: ignore[misc]
    rig.run(frames=20)
    after = rig.cycle.view()
    assert after.raw is not None and np.array_equal(after.raw, MID)
    assert after.pose is not None and after.state is not None
    assert np.array_equal(after.goals_deg, bus.goals[-1])
    assert after.frame_s <= clock.now()
    snap = rig.telemetry.latest()
    assert snap is not None and snap.goals_deg == tuple(bus.goals[-1].tolist())
