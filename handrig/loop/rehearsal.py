"""Rehearsal: the critical path once on scratch state, just before each deadline.

A glove frame is handled by code that ran 5 ms earlier at the latest; in between
the CPU's caches fill with other work (the emulators, the kernel), and a cold
pass costs several times a warm one. So shortly before each deadline the loop
runs the same path (glove decode, controls, orientation, servo step, goal
packet) once on copies: :meth:`handrig.pose.pipeline.PosePipeline.rehearsal_copy`,
copies of the control and orientation objects, and the devices' own ``rehearse``
hooks. Nothing it does reaches the rig, the glove or the bus.
"""

from __future__ import annotations

import copy
from collections.abc import Iterator
from typing import Any

import numpy as np

from handrig.loop.ports import BusLike, ControlsFromRaw, GloveLike, OrientationLike, SampleLike
from handrig.pose.pipeline import PosePipeline


class Rehearsal:
    """Runs the critical path on copies. A control or orientation path that cannot be
    copied (a plain function, a closure: ``copy.deepcopy`` hands those back unchanged,
    so they would see the rehearsal's sample) is not rehearsed."""

    def __init__(self, glove: GloveLike, bus: BusLike, pipeline: PosePipeline,
                 controls_from_raw: ControlsFromRaw, orientation: OrientationLike,
                 period_s: float) -> None:
        self.period_s = period_s
        self.pipeline = pipeline.rehearsal_copy()
        r_controls = copy.deepcopy(controls_from_raw)
        r_orientation = copy.deepcopy(orientation)
        self.controls: ControlsFromRaw | None = (
            None if r_controls is controls_from_raw else r_controls)
        self.orientation: OrientationLike | None = (
            None if r_orientation is orientation else r_orientation)
        self._glove = getattr(glove, "rehearse", None)
        self._write = getattr(bus, "rehearse_write", None)
        self._out = np.zeros(len(pipeline.expander.controls))
        self.sample: SampleLike | None = None  # the newest real sample: what is rehearsed
        self.angles: tuple[float, float] = (0.0, 0.0)  # the live forearm angles

    @property
    def rehearses_controls(self) -> bool:
        return self.controls is not None

    def __call__(self, now_s: float) -> None:
        for _ in self.steps(now_s):
            pass

    def steps(self, now_s: float) -> Iterator[None]:
        """The rehearsal one stage at a time: yields after each stage (glove decode,
        controls, orientation, servo step, goal packet), so that a caller can look at
        the port between stages and stop as soon as a frame is there."""
        sample: Any = self.sample
        if sample is None:
            return
        if self._glove is not None:
            self._glove()
            yield
        out = self._out
        if self.controls is not None:
            self.controls(sample.raw, now_s, out)
            yield
        angles = self.orientation(sample) if self.orientation is not None else self.angles
        yield
        targets = self.pipeline.servo_targets(out, *angles, self.period_s)
        if self._write is not None:
            yield
            self._write(targets)
