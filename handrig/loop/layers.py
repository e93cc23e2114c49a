"""Takes layered under the live glove, inside the loop: :class:`LayerMixer`.

A layer plays a recorded performance (the full pose per frame) onto a group of curves
while the glove drives the rest. Each hand's :class:`~handrig.loop.cycle.Cycle` owns a
mixer; per cycle it

* takes the commands handed to it (:meth:`LayerMixer.post`, from any thread: a deque,
  whose ``append`` and ``popleft`` need no lock; the plans in them were built off the
  loop's thread, :meth:`LayerMixer.plan`);
* finds each layer's pose at its take time (the run's time since the layer's start:
  the run's start for a layer asked for before it, else the cycle that took the
  command), looped or once, and its weight (a smoothstep fade in or out over its
  ``fade_s``, never a jump);
* blends it into the servo targets after the pipeline's step, before the slew limit
  (the same joint and servo limits clamp the blend, then the same slew limit from the
  goals last written), and into the full pose the outputs get, so a recording of a
  layered run holds the whole pose as played.

Nothing is allocated per cycle: the slots, their pose rows and the arrays of every plan
exist before the cycle runs (compiled kernels, :mod:`handrig.pose.layer_kernels`). What
changes rarely (a layer starts, is fully in, fades out, ends) is said as an event and
published as an immutable :attr:`LayerMixer.status` tuple for the panel and the view.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from handrig.pose import layer_kernels as lk
from handrig.pose.pipeline import POSE_SIZE, FloatArray, PosePipeline

__all__ = ["MAX_LAYERS", "LayerCommand", "LayerMixer", "LayerOff", "LayerOn", "LayerPlan",
           "LayerStatus", "smoothstep"]

MAX_LAYERS = 8  # layers at once per hand (a show's few, with room for cross-fades)
IntArray = NDArray[np.intp]
FadeState = Literal["fading in", "on", "fading out"]
_IN, _ON, _OUT, _FREE = 0, 1, 2, 3
_STATE_WORDS: tuple[FadeState, FadeState, FadeState] = ("fading in", "on", "fading out")


def smoothstep(x: float) -> float:
    """0 at x <= 0, 1 at x >= 1, ``3x^2 - 2x^3`` between: no jump in value, none in speed
    at the ends; its steepest slope is 1.5 (at x = 0.5)."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    return x * x * (3.0 - 2.0 * x)


@dataclass(frozen=True)
class LayerPlan:
    """A take on a group of curves, ready for one hand's loop. Read-only.

    ``times_s`` (f,) from 0, increasing; ``poses`` (f, 54) the take's full pose
    (:data:`~handrig.pose.pipeline.POSE_NAMES` order); ``pose_index`` the group's
    indices in the full pose; ``servo_at`` the loop's servos (bus order) whose joints
    are in it and ``servo_cols`` each one's index in the full pose. ``at_start``: the
    take's time 0 is the run's start (else the cycle that takes it)."""

    take: str
    group: str
    times_s: FloatArray
    poses: FloatArray
    pose_index: IntArray
    servo_at: IntArray
    servo_cols: IntArray
    loop: bool
    fade_s: float
    at_start: bool = False

    @property
    def duration_s(self) -> float:
        return float(self.times_s[-1])

    @classmethod
    def build(cls, servo_index: IntArray, take: str, group: str, times_s: FloatArray,
              poses: FloatArray, pose_index: IntArray, *, loop: bool, fade_s: float,
              at_start: bool = False) -> LayerPlan:
        """A plan for a loop whose servos drive the full pose's ``servo_index`` (bus
        order; :attr:`LayerMixer.servo_index`). Pure: any thread may build one."""
        index = np.asarray(pose_index, dtype=np.intp)
        servos = np.asarray(servo_index, dtype=np.intp)
        at = np.flatnonzero(np.isin(servos, index)).astype(np.intp)
        return cls(take, group, np.ascontiguousarray(times_s, dtype=np.float64),
                   np.ascontiguousarray(poses, dtype=np.float64), index, at,
                   servos[at].copy(), loop, float(fade_s), at_start)


@dataclass(frozen=True)
class LayerOn:
    """Start ``plan`` (fading in); a layer already on its group fades out meanwhile."""

    plan: LayerPlan


@dataclass(frozen=True)
class LayerOff:
    """Fade out the layers of take ``take`` (every layer when empty) over ``fade_s``."""

    take: str = ""
    fade_s: float = 0.5


LayerCommand = LayerOn | LayerOff


@dataclass(frozen=True)
class LayerStatus:
    """One layer as the panel shows it: its take, group, loop or once, and fade state."""

    take: str
    group: str
    loop: bool
    state: FadeState
    since_s: float  # the run's time when the state began

    def describe(self) -> str:
        return (f"{self.group} <- {self.take} ({'loop' if self.loop else 'once'}, "
                f"{self.state})")


class _Slot:
    """A layer playing: its plan, where its take started and its fade."""

    __slots__ = ("cursor", "duration_s", "fade_at_s", "fade_len_s", "plan", "row", "start_s",
                 "state", "take_s", "w0", "w1", "weight")

    def __init__(self) -> None:
        self.plan: LayerPlan | None = None
        self.start_s = 0.0
        self.state = _FREE
        self.w0 = self.w1 = self.weight = 0.0
        self.fade_at_s = 0.0
        self.fade_len_s = 0.0
        self.cursor = 0
        self.duration_s = 0.0
        self.take_s = 0.0  # the take's time this cycle
        self.row = np.zeros(POSE_SIZE)  # the take's pose at it (once a mix computed it)

    def fade(self, now_s: float, to: float, length_s: float) -> None:
        self.w0, self.w1 = self.weight, to
        self.fade_at_s, self.fade_len_s = now_s, max(0.0, length_s)


class LayerMixer:
    """The layers of one hand's loop (module docstring), on ``pipeline``'s servos and
    limits. The loop calls :meth:`advance` at the start of each cycle, then
    :meth:`mix_goals` (following the glove) or :meth:`mix_targets` (easing back to it)
    on the servo step, and :meth:`mix_pose` on the full pose for the outputs."""

    def __init__(self, pipeline: PosePipeline) -> None:
        self.servo_index = np.asarray(pipeline.servo_index, dtype=np.intp).copy()
        self.robot = pipeline.robot_path is not None
        self._servo_low, self._servo_high = pipeline.servo_low, pipeline.servo_high
        self._pose_low, self._pose_high = pipeline.pose_low, pipeline.pose_high
        self._inbox: collections.deque[LayerCommand] = collections.deque()
        self._slots = tuple(_Slot() for _ in range(MAX_LAYERS))
        self._live: tuple[_Slot, ...] = ()  # the slots in use, in the order they started
        self.active = 0  # slots in use
        self.t0_s = 0.0  # the run's start (the loop's clock)
        self.status: tuple[LayerStatus, ...] = ()
        """The layers now, for any thread (replaced, never changed, when one changes)."""
        self._events: list[str] = []
        self._row = np.zeros(POSE_SIZE)  # a take's pose at another cycle's time
        lk.warm_up()

    # -- any thread ---------------------------------------------------------------------
    def post(self, command: LayerCommand) -> None:
        """Hand a command to the loop (from any thread); it acts on it next cycle."""
        self._inbox.append(command)

    # -- the loop's thread ----------------------------------------------------------------
    def start(self, t0_s: float) -> None:
        """The run starts at ``t0_s`` (the take time of layers asked for before it)."""
        self.t0_s = t0_s

    def advance(self, now_s: float) -> None:
        """Take the commands handed in, then each layer's take time and weight at
        ``now_s`` (its pose is found by the mix that needs it)."""
        inbox = self._inbox
        while inbox:
            self._command(inbox.popleft(), now_s)
        for slot in self._live:
            plan = slot.plan
            if plan is None:
                continue
            t = now_s - slot.start_s
            duration = slot.duration_s
            if plan.loop and duration > 0.0:
                t %= duration
            elif slot.state != _OUT and t >= duration - plan.fade_s:
                # once: fade out to end with the take (or at once past its end)
                self._set(slot, _OUT, now_s)
                slot.fade(now_s, 0.0, duration - t)
            slot.take_s = t
            span = slot.fade_len_s
            x = 1.0 if span <= 0.0 else (now_s - slot.fade_at_s) / span
            slot.weight = slot.w0 + (slot.w1 - slot.w0) * smoothstep(x)
            if x >= 1.0:
                if slot.state == _IN:
                    self._set(slot, _ON, now_s)
                elif slot.state == _OUT:
                    self._free(slot, now_s)

    def mix_targets(self, raw: FloatArray) -> None:
        """The layers blended into ``raw`` (servo targets before the slew limit), clamped
        to the servo limits."""
        self.mix_goals(raw, raw, raw, -1.0)

    def mix_goals(self, raw: FloatArray, sent: FloatArray, targets: FloatArray,
                  limit_deg: float) -> None:
        """:meth:`mix_targets`, then each layered servo's target (``targets``, the
        pipeline's) at most ``limit_deg`` from ``sent``, the goal last written (a
        negative ``limit_deg``: no slew limit here). One compiled call a layer."""
        low, high = self._servo_low, self._servo_high
        for slot in self._live:
            plan = slot.plan
            if plan is not None and slot.weight > 0.0:
                slot.cursor = lk.layer_goals(
                    plan.times_s, plan.poses, slot.take_s, slot.cursor, slot.row, raw,
                    plan.servo_at, plan.servo_cols, slot.weight, low, high, sent, targets,
                    limit_deg)

    def mix_pose(self, pose: FloatArray, at_s: float | None = None) -> None:
        """The layers blended into the full pose (54), clamped to the joint limits: at
        this cycle's take times, or (``at_s``, the loop's clock) at an earlier cycle's (a
        caught-up frame's pose, output after the newer frame's write)."""
        low, high = self._pose_low, self._pose_high
        for slot in self._live:
            plan = slot.plan
            if plan is not None and slot.weight > 0.0:
                row = slot.row
                if at_s is not None:
                    t = at_s - slot.start_s
                    if plan.loop and slot.duration_s > 0.0:
                        t %= slot.duration_s
                    row = self._row
                    lk.layer_frame(plan.times_s, plan.poses, t, 0, row)
                lk.layer_mix(pose, plan.pose_index, plan.pose_index, row, slot.weight,
                             low, high)

    def drain_events(self) -> list[str]:
        """What the layers did since the last call (layers started, in, out, ended)."""
        if not self._events:
            return []
        events, self._events = self._events, []
        return events

    # -- inside --------------------------------------------------------------------------
    def _command(self, command: LayerCommand, now_s: float) -> None:
        if isinstance(command, LayerOff):
            for slot in self._slots:
                plan = slot.plan
                if (plan is not None and slot.state != _OUT
                        and command.take in ("", plan.take)):
                    self._set(slot, _OUT, now_s)
                    slot.fade(now_s, 0.0, command.fade_s * slot.weight)
            return
        plan = command.plan
        free = None
        for slot in self._slots:
            other = slot.plan
            if other is None:
                free = free or slot
            elif other.group == plan.group and slot.state != _OUT:
                self._set(slot, _OUT, now_s)  # a cross-fade: the new layer fades in
                slot.fade(now_s, 0.0, plan.fade_s * slot.weight)
        if free is None:
            self._events.append(f"layer {plan.group} <- {plan.take} refused: "
                                f"{MAX_LAYERS} layers play already")
            return
        free.plan = plan
        free.start_s = self.t0_s if plan.at_start else now_s
        free.duration_s = plan.duration_s
        free.take_s = now_s - free.start_s
        free.cursor = 0
        free.weight = 0.0
        free.fade(now_s, 1.0, plan.fade_s)
        self._live = (*self._live, free)
        lk.layer_frame(plan.times_s, plan.poses, 0.0, 0, free.row)
        self.active += 1
        self._set(free, _IN, now_s)

    def _set(self, slot: _Slot, state: int, now_s: float) -> None:
        slot.state = state
        self._publish(now_s, slot)

    def _free(self, slot: _Slot, now_s: float) -> None:
        plan = slot.plan
        slot.plan, slot.state, slot.weight = None, _FREE, 0.0
        self._live = tuple(s for s in self._live if s is not slot)
        self.active -= 1
        if plan is not None:
            self._events.append(f"layer {plan.group} <- {plan.take} ended")
        self._publish(now_s, None)

    def _publish(self, now_s: float, changed: _Slot | None) -> None:
        since = now_s - self.t0_s
        old = {(s.take, s.group): s for s in self.status}
        out = []
        for slot in self._slots:
            plan = slot.plan
            if plan is None:
                continue
            word = _STATE_WORDS[slot.state]
            prev = old.get((plan.take, plan.group))
            keep = prev is not None and prev.state == word and slot is not changed
            out.append(LayerStatus(plan.take, plan.group, plan.loop, word,
                                   prev.since_s if keep and prev is not None else since))
        if changed is not None and changed.plan is not None:
            p = changed.plan
            self._events.append(f"layer {p.group} <- {p.take} ({'loop' if p.loop else 'once'})"
                                f" {_STATE_WORDS[changed.state]}")
        self.status = tuple(out)
