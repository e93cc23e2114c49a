"""A telemetry snapshot as the page's JSON frame (and the scene message sent once).

One frame is encoded per published snapshot, whatever the number of browsers: the
server sends the same text to each. Numbers are rounded to what the page shows.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from handrig.app.view.scene import ModelScene
from handrig.config.rig import HAND_NAMES

if TYPE_CHECKING:
    from handrig.loop.telemetry import LoopSnapshot


def _num(x: float | None, nd: int = 2) -> float | None:
    if x is None:
        return None
    x = float(x)
    return round(x, nd) if math.isfinite(x) else None


def _nums(xs: Sequence[float | None], nd: int = 2) -> list[float | None]:
    return [_num(x, nd) for x in xs]


def _plain(value: Any) -> Any:
    """A status record's field as JSON (dataclasses, enums, tuples, paths)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, enum.Enum):
        return _plain(value.value)
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, float):
        return _num(value, 3)
    if value is None or isinstance(value, bool | int | str):
        return value
    return str(value)


class FrameEncoder:
    """Turns snapshots into the page's messages. ``models``: the rig's MuJoCo models by
    hand (:class:`ModelScene`); ``skeletons``: the human-hand model of each hand the
    pose holds, for the skeleton of the full pose."""

    def __init__(self, models: Mapping[str, ModelScene], skeletons: Mapping[str, ModelScene],
                 *, title: str = "handrig", actions: Sequence[str] = ("relax", "stop", "estop")
                 ) -> None:
        self.models = dict(models)
        self.skeletons = dict(skeletons)
        self.title = title
        self.actions = tuple(actions)

    def scene(self) -> str:
        """The message a browser gets first: the models' geometry and what it can do."""
        return json.dumps({
            "type": "scene", "title": self.title, "actions": list(self.actions),
            "models": {h: s.geometry() for h, s in self.models.items()},
            "rest": {h: s.pose({}) for h, s in self.models.items()},
            "skeleton_hands": list(self.skeletons),
        }, separators=(",", ":"))

    def frame(self, snap: LoopSnapshot | HandsSnapshot) -> str:
        """One snapshot as the page's frame message: a part per hand in ``hands`` (its
        loop's figures, its glove's controls, its servos), whatever the number of hands
        (a bare :class:`LoopSnapshot` is one loop driving the whole rig). Each model is
        posed from the loop that drives it, each skeleton from its own hand's pose."""
        hands_snap = snap if isinstance(snap, HandsSnapshot) else HandsSnapshot({"": snap})
        hands: list[dict[str, Any]] = []
        bodies: dict[str, Any] = {}
        ghosts: dict[str, Any] = {}
        skeleton: dict[str, Any] = {}
        for key, one in hands_snap.hands.items():
            source, angles, ghost = _angles(one)
            own = tuple(n for n in one.control_names if not key or n.startswith(key))
            hands.append({"hand": key, "label": HAND_NAMES.get(key, ""), "source": source,
                          **_hand_fields(one, own)})
            for h, model in self.models.items():
                if key in ("", h):
                    bodies[h] = model.pose(angles)
                    if ghost is not None:
                        ghosts[h] = model.pose(ghost)
            for h, human in self.skeletons.items():
                if key in ("", h) and any(n.startswith(h) for n in one.curve_names):
                    skeleton[h] = human.skeleton(_pose(one))
        first = next(iter(hands_snap.hands.values()))
        msg: dict[str, Any] = {
            "type": "frame", "seq": int(hands_snap.seq), "t_s": _num(first.t_s, 3),
            "hands": hands,
            "outputs": [_plain(o) for one in hands_snap.hands.values() for o in one.outputs],
            "layers": list(dict.fromkeys(x for one in hands_snap.hands.values()
                                         for x in one.layers)),
            "bodies": bodies, "ghost": ghosts or None, "skeleton": skeleton,
            "cues": list(hands_snap.cues),
        }
        return json.dumps(msg, separators=(",", ":"))


@dataclass(frozen=True)
class HandsSnapshot:
    """The snapshots of a session's loops, by hand (``"ri"``, ``"le"``; ``""`` for one
    loop driving the whole rig), taken together by the view's feeder. ``seq`` changes
    whenever any hand's does. ``cues``: the last few cues taken (OSC, MIDI, the ``r``
    key), each naming its source, newest last."""

    hands: Mapping[str, LoopSnapshot]
    cues: tuple[str, ...] = ()

    @property
    def seq(self) -> int:
        return sum(int(s.seq) for s in self.hands.values())


def _pose(snap: LoopSnapshot) -> dict[str, float]:
    return {n: float(v) for n, v in zip(snap.curve_names, snap.pose_deg, strict=False)}


def _angles(snap: LoopSnapshot) -> tuple[str, dict[str, float], dict[str, float] | None]:
    """What the model is posed from (``positions``, ``goals`` or ``pose``), the joint
    angles, and the ghost's (the goals; None unless there are readings and goals)."""
    pose = _pose(snap)
    reported = {j: float(p) for j, p in zip(snap.servo_joints, snap.positions_deg,
                                            strict=False) if p is not None}
    goals = {j: float(g) for j, g in zip(snap.servo_joints, snap.goals_deg, strict=False)
             if g is not None}
    if reported:
        source, angles = "positions", {**pose, **goals, **reported}
    elif goals:
        source, angles = "goals", {**pose, **goals}
    else:
        source, angles = "pose", dict(pose)
    return source, angles, ({**pose, **goals} if reported and goals else None)


def _hand_fields(snap: LoopSnapshot, controls: tuple[str, ...]) -> dict[str, Any]:
    """One loop's figures, its glove (the ``controls`` named, calibrated, each with its
    channel's raw count) and its servos."""
    index = {n: i for i, n in enumerate(snap.control_names)}
    calibrated = [snap.controls[index[n]] if index[n] < len(snap.controls) else None
                  for n in controls]
    raw = [snap.raw[index[n]] if index[n] < len(snap.raw) else None for n in controls]
    return {
        "mode": str(snap.mode), "mode_reason": str(snap.mode_reason),
        "rate_hz": _num(snap.rate_hz, 1), "latency_p50_us": _num(snap.latency_p50_us, 0),
        "latency_p99_us": _num(snap.latency_p99_us, 0), "frames_lost": int(snap.frames_lost),
        "cycles": int(snap.cycles), "overruns": int(snap.overruns),
        "glove": {
            "connected": bool(snap.glove_connected),
            "names": list(controls), "controls": _nums(calibrated, 3),
            "raw": _nums(raw, 0), "inclination_deg": _num(snap.inclination_deg, 1),
            "rotation_deg": _num(snap.rotation_deg, 1),
        },
        "servos": {
            "ids": [int(i) for i in snap.servo_ids], "joints": list(snap.servo_joints),
            "goal_deg": _nums(snap.goals_deg, 1), "position_deg": _nums(snap.positions_deg, 1),
            "temperature_c": _nums(snap.temperatures_c, 0),
            "errors": [int(e) for e in snap.hardware_errors],
            "stale": [bool(s) for s in snap.stale],
        },
    }
