"""What the loop needs from its dependencies.

The devices are the abstract classes that list everything the loop uses:
:class:`~handrig.devices.glove.source.GloveSource`,
:class:`~handrig.devices.servo.bus.ServoBus` and
:class:`~handrig.outputs.base.Output` (a plain callable ``(t_s, pose)`` is an output
too). The control path and the forearm orientation are callables.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from handrig.devices.glove.source import GloveSample, GloveSource
from handrig.devices.servo.bus import ServoBus, ServoState

FloatArray = NDArray[np.float64]
OutputLike = Callable[[float, FloatArray], None]

__all__ = ["ControlsFromRaw", "FloatArray", "GloveSample", "GloveSource", "OrientationLike",
           "OutputLike", "ServoBus", "ServoState"]


class ControlsFromRaw(Protocol):
    def __call__(self, raw: FloatArray, t_s: float, out: FloatArray) -> FloatArray: ...


class OrientationLike(Protocol):
    def __call__(self, sample: GloveSample) -> tuple[float, float]: ...
