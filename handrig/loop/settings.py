"""What a loop is built from, as data: its parts and its settings.

:class:`~handrig.loop.rig.Rig` and :class:`~handrig.loop.cycle.Cycle` take these two
records instead of long keyword lists. :class:`LoopParts` are the objects the loop
runs on (nothing in it opens a device: the factory, or a test, builds them);
:class:`RigSettings` are the rig file's numbers the loop follows (its ``[loop]``, the
read schedule of its ``[bus]``, ``[silence]``, ``[heat]``) and two switches of the run.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from handrig.clock import Clock
from handrig.config.rig import BusConfig, HeatConfig, LoopConfig, RigConfig, SilenceConfig
from handrig.loop.ports import ControlsFromRaw, GloveSource, OrientationLike, ServoBus
from handrig.pose.gravity import GravityCompensation
from handrig.pose.pipeline import PosePipeline

__all__ = ["LoopParts", "RigSettings"]


@dataclass(frozen=True)
class LoopParts:
    """The objects one hand's loop runs on.

    ``controls_from_raw`` turns a glove sample's raw channels into the pipeline's
    controls, ``orientation`` a sample into the forearm's (inclination, rotation) in
    degrees. ``raw_channels``: the raw channel driving each control, in control order
    (-1: none), so that the telemetry shows each control beside its own channel's
    count (empty: the glove's channels in their own order).
    """

    glove: GloveSource
    bus: ServoBus
    pipeline: PosePipeline
    clock: Clock
    controls_from_raw: ControlsFromRaw
    orientation: OrientationLike
    raw_channels: tuple[int, ...] = ()
    gravity: GravityCompensation | None = None
    """A robot hand's goals moved against gravity's pull as they go to the bus (the
    loop's own goals, its slew limit and easing stay the uncompensated ones)."""


@dataclass(frozen=True)
class RigSettings:
    """The numbers the loop follows; the defaults are the config's.

    ``loop``: the trigger (``mode``, ``rate_hz``, ``floor_hz``, ``ceiling_hz``,
    ``catch_up``) and the safety timings (``glove_timeout_s``, ``relax_time_s``,
    ``resume_frames``, ``resume_time_s``); ``bus``: the read schedule
    (``read_every``, ``read_parts``; the rest of it is the bus's own);
    ``silence`` and ``heat``: the tiers for servos that stop answering or warm up.
    ``ease_in``: the first frame eases the servos in from where they are over
    ``resume_time_s`` (a take played onto the rig) instead of the slew limit alone.
    ``profile``: time the critical path's stages (``Rig.stage_profile``).
    """

    loop: LoopConfig = field(default_factory=LoopConfig)
    bus: BusConfig = field(default_factory=BusConfig)
    silence: SilenceConfig = field(default_factory=SilenceConfig)
    heat: HeatConfig = field(default_factory=HeatConfig)
    ease_in: bool = False
    profile: bool = False

    @classmethod
    def from_config(cls, config: RigConfig, *, ease_in: bool = False,
                    profile: bool = False) -> RigSettings:
        """A rig file's ``[loop]``, ``[bus]``, ``[silence]`` and ``[heat]``."""
        return cls(loop=config.loop, bus=config.bus, silence=config.silence,
                   heat=config.heat, ease_in=ease_in, profile=profile)

    @property
    def read_every(self) -> int:
        """A present-state read every this many cycles (at least 1)."""
        return max(1, int(self.bus.read_every))

    @property
    def read_parts(self) -> int:
        """Each read asks this share of the servos, in turn (1: all at once)."""
        return max(1, int(self.bus.read_parts))
