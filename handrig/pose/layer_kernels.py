"""Compiled kernels of take layering (numba): a take's pose at a time, mixed into the live one.

A layer (:mod:`handrig.loop.layers`) plays a recorded performance onto a group of
curves while the glove drives the rest. Per cycle and layer, :func:`layer_frame`
interpolates the take's full pose at the take's time, :func:`layer_mix` blends it into
the live values (the servo targets before the slew limit, or the full pose) with the
layer's weight and clamps to the limits, and :func:`layer_slew` slew-limits the
layered servos from the goals last sent. Plain loops, no allocation; :func:`warm_up`
compiles (or loads from the cache) them before a loop starts.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def layer_frame(times: Any, poses: Any, t: float, cursor: int, row: Any
                ) -> int:  # pragma: no cover - compiled
    """``row`` (m,) becomes the take's pose at take time ``t``: linear between the frames
    around it (``times`` (f,) increasing from 0, ``poses`` (f, m)); before the first frame
    the first, after the last the last. ``cursor`` is the frame found last time (the
    search walks on from it; a time before it starts again at 0); returns the new one."""
    f = times.shape[0]
    if cursor < 0 or cursor >= f or t < times[cursor]:
        cursor = 0
    while cursor + 1 < f and times[cursor + 1] <= t:
        cursor += 1
    m = row.shape[0]
    if cursor + 1 < f and t > times[cursor]:
        frac = (t - times[cursor]) / (times[cursor + 1] - times[cursor])
        for j in range(m):
            a = poses[cursor, j]
            row[j] = a + frac * (poses[cursor + 1, j] - a)
    else:
        for j in range(m):
            row[j] = poses[cursor, j]
    return cursor


@njit(cache=True, nogil=True)
def layer_mix(values: Any, at: Any, cols: Any, row: Any, weight: float, low: Any,
              high: Any) -> None:  # pragma: no cover - compiled
    """``values[at[i]]`` moves ``weight`` (0..1) of the way to ``row[cols[i]]``, then is
    clamped to ``[low, high]`` at ``at[i]``. A non-finite take value leaves the live one."""
    for i in range(at.shape[0]):
        k = at[i]
        v = row[cols[i]]
        if not math.isfinite(v):
            continue
        live = values[k]
        v = live + weight * (v - live)
        values[k] = min(max(v, low[k]), high[k])


@njit(cache=True, nogil=True)
def layer_goals(times: Any, poses: Any, t: float, cursor: int, row: Any, values: Any, at: Any,
                cols: Any, weight: float, low: Any, high: Any, sent: Any, targets: Any,
                limit: float) -> int:  # pragma: no cover - compiled
    """One layer's step before the write, in one call: :func:`layer_frame` (``row`` the
    take's pose at ``t``; returns the cursor), :func:`layer_mix` into ``values`` (the servo
    targets before the slew limit), then, unless ``limit`` is negative,
    :func:`layer_slew` of the layered servos into ``targets``."""
    cursor = layer_frame(times, poses, t, cursor, row)
    layer_mix(values, at, cols, row, weight, low, high)
    if limit >= 0.0:
        layer_slew(values, sent, targets, at, limit)
    return cursor


@njit(cache=True, nogil=True)
def layer_slew(raw: Any, sent: Any, targets: Any, at: Any,
               limit: float) -> None:  # pragma: no cover - compiled
    """``targets[k]`` for each ``k`` in ``at``: at most ``limit`` from ``sent[k]`` (the
    goal last written) toward ``raw[k]`` (the layered target before the slew limit)."""
    for i in range(at.shape[0]):
        k = at[i]
        step = min(max(raw[k] - sent[k], -limit), limit)
        targets[k] = sent[k] + step


def warm_up() -> None:
    """Compile (or load from the cache) every kernel with the types the loop uses."""
    times = np.array([0.0, 1.0])
    poses = np.zeros((2, 3))
    row = np.zeros(3)
    idx = np.zeros(1, np.intp)
    layer_frame(times, poses, 0.5, 0, row)
    layer_mix(row, idx, idx, row, 0.5, row - 1.0, row + 1.0)
    layer_slew(row, row, row, idx, 1.0)
    layer_goals(times, poses, 0.5, 0, row, row, idx, idx, 0.5, row - 1.0, row + 1.0, row, row,
                1.0)
