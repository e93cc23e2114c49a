"""A loop on the shared fakes: :func:`make_rig` and the settings it takes as keywords."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from handrig.config.rig import BusConfig, HeatConfig, LoopConfig, SilenceConfig
from handrig.loop.rig import Rig
from handrig.loop.settings import LoopParts, RigSettings
from handrig.loop.trigger import Trigger

MID = np.array([2000.0, 2100.0, 2000.0, 2100.0, 2100.0])
"""Mid-range raw counts of the shipped glove's five channels."""

_LOOP_KEYS = {f.name for f in dataclasses.fields(LoopConfig)}
_BUS_KEYS = {f.name for f in dataclasses.fields(BusConfig)}


def loop_settings(*, silence: SilenceConfig | None = None, heat: HeatConfig | None = None,
                  ease_in: bool = False, profile: bool = False, **kw: Any) -> RigSettings:
    """:class:`RigSettings` from keywords: ``[loop]`` keys (``mode``, ``rate_hz``,
    ``floor_hz``, ...) and ``[bus]`` keys (``read_every``, ``read_parts``) by name; an
    unknown key is a TypeError naming it."""
    unknown = set(kw) - _LOOP_KEYS - _BUS_KEYS
    if unknown:
        raise TypeError(f"loop_settings: unknown keys {sorted(unknown)}; use [loop] keys "
                        f"{sorted(_LOOP_KEYS)} or [bus] keys {sorted(_BUS_KEYS)}")
    loop = LoopConfig(**{k: v for k, v in kw.items() if k in _LOOP_KEYS})
    bus = BusConfig(**{k: v for k, v in kw.items() if k in _BUS_KEYS})
    return RigSettings(loop=loop, bus=bus, silence=silence or SilenceConfig(),
                       heat=heat or HeatConfig(), ease_in=ease_in, profile=profile)


def rig_on(parts: Any, glove: Any, bus: Any, clock: Any, *,
           controls_from_raw: Any = None, raw_channels: Sequence[int] = (),
           outputs: Sequence[Callable[[float, Any], None]] = (),
           trigger: Trigger | None = None, log: Callable[[str], None] = lambda s: None,
           **settings: Any) -> Rig:
    """A :class:`Rig` on ``glove`` and ``bus`` with the app's pipeline, control path and
    orientation (``parts``: :func:`handrig.app.parts.build_parts`'s), the settings as
    keywords (:func:`loop_settings`)."""
    loop_parts = LoopParts(glove, bus, parts.pipeline, clock,
                           controls_from_raw=controls_from_raw or parts.controls,
                           orientation=parts.orientation,
                           raw_channels=tuple(raw_channels))
    return Rig(loop_parts, loop_settings(**settings), outputs=outputs, log=log,
               trigger=trigger)


def make_rig(parts: Any, glove: Any, bus: Any, clock: Any, **kw: Any) -> Rig:
    """The loop tests' rig: fixed at 200 Hz unless told, no catching up unless told, a
    read every 4 cycles, a 0.25 s glove timeout, relaxing in 0.5 s."""
    kw.setdefault("mode", kw.pop("loop_mode", "fixed"))
    kw.setdefault("catch_up", False)
    kw.setdefault("rate_hz", 200.0)
    kw.setdefault("read_every", 4)
    kw.setdefault("glove_timeout_s", 0.25)
    kw.setdefault("relax_time_s", 0.5)
    return rig_on(parts, glove, bus, clock, **kw)


def relaxed_targets(parts: Any, inclination: float = 0.0, rotation: float = 0.0) -> np.ndarray:
    """The servo targets of the relaxed pose at a forearm orientation, clamped."""
    pl = parts.pipeline
    relaxed = np.clip(pl.relaxed_pose(inclination, rotation), pl.pose_low, pl.pose_high)
    return np.asarray(np.clip(relaxed[pl.servo_index], pl.servo_low, pl.servo_high))
