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
from typing import TYPE_CHECKING, Any

from handrig.app.view.scene import ModelScene

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

    def frame(self, snap: LoopSnapshot) -> str:
        """One snapshot as the page's frame message."""
        pose = {n: float(v) for n, v in zip(snap.curve_names, snap.pose_deg, strict=False)}
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
        ghost = {**pose, **goals}
        msg: dict[str, Any] = {
            "type": "frame", "seq": int(snap.seq), "t_s": _num(snap.t_s, 3),
            "mode": str(snap.mode), "mode_reason": str(snap.mode_reason),
            "rate_hz": _num(snap.rate_hz, 1), "latency_p50_us": _num(snap.latency_p50_us, 0),
            "latency_p99_us": _num(snap.latency_p99_us, 0), "frames_lost": int(snap.frames_lost),
            "cycles": int(snap.cycles), "overruns": int(snap.overruns),
            "glove": {
                "connected": bool(snap.glove_connected),
                "names": list(snap.control_names), "controls": _nums(snap.controls, 3),
                "raw": _nums(snap.raw, 0), "inclination_deg": _num(snap.inclination_deg, 1),
                "rotation_deg": _num(snap.rotation_deg, 1),
            },
            "servos": {
                "ids": [int(i) for i in snap.servo_ids], "joints": list(snap.servo_joints),
                "goal_deg": _nums(snap.goals_deg, 1), "position_deg": _nums(snap.positions_deg, 1),
                "temperature_c": _nums(snap.temperatures_c, 0),
                "errors": [int(e) for e in snap.hardware_errors],
                "stale": [bool(s) for s in snap.stale],
            },
            "outputs": [_plain(o) for o in snap.outputs],
            "source": source,
            "bodies": {h: s.pose(angles) for h, s in self.models.items()},
            "ghost": ({h: s.pose(ghost) for h, s in self.models.items()}
                      if reported and goals else None),
            "skeleton": {h: s.skeleton(pose) for h, s in self.skeletons.items()
                         if any(n.startswith(h) for n in snap.curve_names)},
        }
        return json.dumps(msg, separators=(",", ":"))
