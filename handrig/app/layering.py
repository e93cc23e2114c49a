"""Takes layered under the live glove, on the control side: :class:`LayerControl`.

``--layer TAKE:GROUP`` (``run``, ``demo``, ``play``), a show file's ``[[layer]]`` tables
and the cues (``/handrig/play NAME``, ``/handrig/layer NAME GROUP``) all come here. A
take is a performance (CSV or BVH from ``--record``: the full pose per frame), named by
the show file's ``[takes]`` table or given as a file; a group is a hand, a finger, the
wrist or a list of curves (:mod:`handrig.config.layer_groups`). Everything is read and
checked here, off the loop's thread, before it is handed to each hand's loop as a
:class:`~handrig.loop.layers.LayerPlan` (:meth:`~handrig.loop.layers.LayerMixer.post`:
no lock, nothing allocated on the loop's side). The loop blends it in, fades it in and
out, with the live pose's limits and slew limit (:mod:`handrig.loop.layers`).

The session builds one :class:`LayerControl` (:meth:`LayerControl.for_session`: the
layers asked for at the start checked before any bus opens) and connects it to the
hands' loops once they exist; :attr:`LayerOptions.on_control` is how a caller (the cues)
gets it. ``play(name)`` and ``layer(name, group)`` are safe from any thread.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from handrig.app.hands import SessionParts
from handrig.app.takes import performance_poses, take_kind
from handrig.config.layer_groups import DEFAULT_FADE_S, FADE_RANGE_S, OFF, group_joints
from handrig.errors import ConfigError, DataError
from handrig.loop.layers import LayerCommand, LayerOff, LayerOn, LayerPlan, LayerStatus
from handrig.loop.rig import Rig
from handrig.pose.pipeline import POSE_NAMES, FloatArray, PosePipeline, pose_index

_WRIST = np.array([pose_index(n) for n in POSE_NAMES if "Wrist" in n], dtype=np.intp)


@dataclass(frozen=True)
class LayerSpec:
    """A layer asked for at the start: ``take`` (a ``[takes]`` name or a file), ``group``,
    looped or once, its fade; ``key``/``file``: where it was asked for (for errors)."""

    take: str
    group: str
    loop: bool = True
    fade_s: float = DEFAULT_FADE_S
    key: str = "--layer"
    file: str | None = None


@dataclass(frozen=True)
class LayerOptions:
    """A session's layering: the show's ``takes`` (name -> file), the ``layers`` that
    play from the run's start, the fade of the cues' layers, and ``on_control``, given
    the :class:`LayerControl` once the loops exist (the cues' ``play``/``layer``)."""

    takes: Mapping[str, str] = field(default_factory=dict)
    layers: tuple[LayerSpec, ...] = ()
    fade_s: float = DEFAULT_FADE_S
    on_control: Callable[[LayerControl], None] | None = None


def parse_layer_flag(text: str) -> LayerSpec:
    """``--layer TAKE:GROUP[:once|:loop]`` (default loop); ConfigError naming the flag."""
    head, _, last = text.rpartition(":")
    loop = True
    if last.strip().lower() in ("once", "loop") and ":" in head:
        loop = last.strip().lower() == "loop"
        head, _, last = head.rpartition(":")
    if not head or not last.strip():
        raise ConfigError("expected TAKE:GROUP", key="--layer", value=text,
                          allowed="a take (a [takes] name or a .csv/.bvh performance) and a"
                          " group, e.g. --layer left_take.csv:left or take.csv:right.index:once")
    return LayerSpec(head, last.strip(), loop=loop)


@dataclass(frozen=True)
class LayerTake:
    """A performance read for layering: ``times_s`` from 0, ``poses`` (f, 54);
    ``has_wrist``: whether it holds the wrist DOFs."""

    name: str
    path: Path
    times_s: FloatArray
    poses: FloatArray
    has_wrist: bool


def load_layer_take(name: str, path: str | Path, *, key: str = "--layer",
                    file: str | None = None) -> LayerTake:
    """Read a performance to layer (DataError, or ConfigError at ``key``, naming it)."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"no such take: {p}", file=file, key=key, value=name,
                          allowed="a performance .csv/.bvh recorded with --record, or a"
                          " name from the show file's [takes]")
    if take_kind(p) == "glove":
        raise ConfigError(f"{p} is a glove take: a layer plays a performance (the pose)",
                          file=file, key=key, value=name,
                          allowed="a take recorded with --record (.csv or .bvh)")
    t, full, has_wrist = performance_poses(p)
    if len(t) < 2:
        raise DataError(f"{p}: {len(t)} frame: a layer needs two frames or more")
    return LayerTake(name, p, t - t[0], np.ascontiguousarray(full), has_wrist)


class LayerControl:
    """Layers onto the hands' loops (module docstring). ``pipelines``: each hand's, in
    hand order; ``takes``: the show's named takes (read and checked here)."""

    def __init__(self, pipelines: Sequence[PosePipeline],
                 takes: Mapping[str, str] | None = None, *, fade_s: float = DEFAULT_FADE_S,
                 file: str | None = None) -> None:
        self._servo_index = [np.asarray(p.servo_index, dtype=np.intp) for p in pipelines]
        self._robot = any(p.robot_path is not None for p in pipelines)
        self.hands = frozenset(j[:2] for p in pipelines for j in p.servo_joints
                               if j[:2] in ("ri", "le"))
        self.fade_s = _fade(fade_s, "fade_s", file)
        self._paths = dict(takes or {})
        self._file = file
        self._lock = threading.Lock()  # the control side's only: takes read, mixers set
        self._takes = {name: load_layer_take(name, path, key=f"takes.{name}", file=file)
                       for name, path in self._paths.items()}
        self._rigs: tuple[Rig, ...] = ()
        self._pending: list[tuple[LayerCommand | None, ...]] = []
        self.on_control: Callable[[LayerControl], None] | None = None

    @classmethod
    def for_session(cls, parts: SessionParts, options: LayerOptions | None) -> LayerControl:
        """The session's control, with the layers asked for at the start planned (their
        takes read, their groups checked against the puppet) before any bus opens."""
        options = options or LayerOptions()
        control = cls([side.pipeline for side in parts.hands], options.takes,
                      fade_s=options.fade_s)
        for spec in options.layers:
            control._post(control._plans(spec.take, spec.group, loop=spec.loop,
                                         fade_s=_fade(spec.fade_s, _sub(spec.key, "fade_s"),
                                                      spec.file),
                                         at_start=True, key=spec.key, file=spec.file))
        control.on_control = options.on_control
        return control

    # -- the seam: any thread -----------------------------------------------------------
    def play(self, name: str) -> None:
        """Take ``name`` onto every curve of the puppet, once, fading in and back out to
        the live glove. ConfigError for an unknown take."""
        self._post(self._plans(name, "all", loop=False, fade_s=self.fade_s, key="play"))

    def layer(self, name: str, group: str) -> None:
        """Take ``name`` onto ``group``, looped, fading in (a layer on that group fades
        out meanwhile); ``group`` ``"off"`` fades the take's layers out (``name`` ``"*"``:
        every layer). ConfigError for an unknown take or group."""
        if group.strip().lower() == OFF:
            if name != "*":
                self._take(name, "layer", None)
            off = LayerOff("" if name == "*" else name, self.fade_s)
            self._post(tuple(off for _ in self._servo_index))
            return
        self._post(self._plans(name, group, loop=True, fade_s=self.fade_s, key="layer"))

    def status(self) -> tuple[LayerStatus, ...]:
        """The layers playing now, every hand's (a layer on several hands once)."""
        seen: dict[tuple[str, str], LayerStatus] = {}
        for rig in self._rigs:
            for s in rig.cycle.layers.status:
                seen.setdefault((s.take, s.group), s)
        return tuple(seen.values())

    # -- the session ----------------------------------------------------------------------
    def connect(self, rigs: Sequence[Rig]) -> None:
        """The hands' loops (hand order): what was asked for so far goes to them."""
        with self._lock:
            self._rigs = tuple(rigs)
            for commands in self._pending:
                self._send(commands)
            self._pending.clear()
        if self.on_control is not None:
            self.on_control(self)

    # -- inside ---------------------------------------------------------------------------
    def _post(self, commands: tuple[LayerCommand | None, ...]) -> None:
        with self._lock:
            if self._rigs:
                self._send(commands)
            else:
                self._pending.append(commands)

    def _send(self, commands: tuple[LayerCommand | None, ...]) -> None:
        for rig, command in zip(self._rigs, commands, strict=True):
            if command is not None:
                rig.cycle.layers.post(command)

    def _take(self, name: str, key: str, file: str | None) -> LayerTake:
        with self._lock:
            take = self._takes.get(name)
        if take is not None:
            return take
        if not Path(name).is_file():
            names = ", ".join(sorted(self._takes)) or "none"
            looks_a_file = "/" in name or Path(name).suffix.lower() in (".csv", ".bvh")
            raise ConfigError("no such take" if looks_a_file else "unknown take",
                              file=file, key=key, value=name,
                              allowed=f"a name from the show file's [takes] ({names}) or a"
                              " performance .csv/.bvh")
        take = load_layer_take(name, name, key=key, file=file)
        with self._lock:
            return self._takes.setdefault(name, take)

    def _plans(self, name: str, group: str, *, loop: bool, fade_s: float, key: str,
               at_start: bool = False, file: str | None = None
               ) -> tuple[LayerOn | None, ...]:
        """A plan per hand's loop: those whose servos the group moves, and the first
        (whose full pose the outputs get); ConfigError for an unknown take or group, a
        group that moves no servo, a robot hand."""
        gkey = _sub(key, "group") if file is not None else key
        if self._robot:
            raise ConfigError("a robot hand's servos follow retargeted curves: layering"
                              " needs a human rig", file=file, key=gkey, value=group,
                              allowed="a puppet rig (e.g. puppet_two_hands)")
        joints = group_joints(group, self.hands, key=gkey)
        take = self._take(name, _sub(key, "take") if file is not None else key, file)
        index = np.array([pose_index(j) for j in joints], dtype=np.intp)
        if not take.has_wrist:  # the wrist stays the glove's
            index = index[~np.isin(index, _WRIST)]
        if not any(np.isin(servos, index).any() for servos in self._servo_index):
            raise ConfigError(f"group {group!r} moves no servo of this rig", file=file,
                              key=gkey, value=group,
                              allowed="a group with a joint the rig's servos drive")
        if not loop:  # once: the fade in and the fade out fit in the take
            fade_s = min(fade_s, float(take.times_s[-1]) / 2.0)
        return tuple(LayerOn(LayerPlan.build(servos, name, group, take.times_s, take.poses,
                                             index, loop=loop, fade_s=fade_s,
                                             at_start=at_start))
                     if i == 0 or np.isin(servos, index).any() else None
                     for i, servos in enumerate(self._servo_index))


def _fade(value: float, key: str, file: str | None) -> float:
    low, high = FADE_RANGE_S
    if not (math.isfinite(value) and low <= value <= high):
        raise ConfigError("fade out of range", file=file, key=key, value=value,
                          allowed=f"{low:g}..{high:g} seconds")
    return float(value)


def _sub(key: str, part: str) -> str:
    """A show file's key and its part (``layer[0].group``); a flag stays itself."""
    return key if key.startswith("-") else f"{key}.{part}"
