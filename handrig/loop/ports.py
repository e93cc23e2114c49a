"""What the loop needs from its dependencies (structural types: any object that fits)."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


class SampleLike(Protocol):
    raw: FloatArray
    quat: FloatArray | None
    estop: bool
    host_time_s: float


class GloveLike(Protocol):
    def latest(self) -> Any: ...


class ControlsFromRaw(Protocol):
    def __call__(self, raw: FloatArray, t_s: float, out: FloatArray) -> FloatArray: ...


class OrientationLike(Protocol):
    def __call__(self, sample: Any) -> tuple[float, float]: ...


class BusLike(Protocol):
    def write_goals_deg(self, goals_deg: FloatArray) -> int: ...

    def read_state(self, deadline_s: float | None = None,
                   part: tuple[int, int] | None = None) -> Any: ...

