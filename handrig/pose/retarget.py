"""Retarget: the 50 human curves -> a robot hand's joints, one linear step.

A retarget table (TOML, e.g. ``config/rigs/leap_retarget.toml``) gives, for each
robot joint, its source curve or curves with a gain each, an offset and the
robot's range::

    format = "handrig-retarget"
    version = 1

    [joints.if_mcp]                       # a joint of the robot's MJCF model
    sources = { riIndexMCPy = 1.0 }       # curve name -> gain (deg per deg)
    offset_deg = 0.0
    range_deg = [-17.9, 127.7]            # the robot joint's range, degrees

Human angles are in the vocabulary convention (degrees, flexion positive); robot
angles in the model's own convention (the MJCF joint angle in degrees). The whole
table compiles to one matrix::

    robot = clip(offset_deg + G @ human50, low_deg, high_deg)

with ``G`` of shape (robot joints, 50), rows in table order. :func:`retarget` is
that step as a pure function that allocates nothing when given ``out``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.config.loading import load
from handrig.errors import ConfigError, DataError
from handrig.pose.mjcf import MjcfJoint

FloatArray = NDArray[np.float64]
FORMAT = "handrig-retarget"
MAX_GAIN = 10.0  # |gain| above this is a typo, not a mapping (deg per deg)


@dataclass(frozen=True)
class RetargetJoint:
    """One robot joint: its sources (curve -> gain), offset and range, degrees."""

    range_deg: tuple[float, float]
    sources: dict[str, float] = field(default_factory=dict)
    offset_deg: float = 0.0
    note: str = ""

    def check(self) -> None:
        for name, gain in self.sources.items():
            if name not in hand.CURVE_NAMES:
                if hand.is_joint_name(name):
                    detail = "a wrist DOF, not one of the 50 curves the retarget reads"
                else:
                    try:
                        hand.curve(name)
                        detail = "unknown curve"
                    except hand.UnknownJointError as exc:
                        detail = str(exc)
                raise ConfigError(detail, key=f"sources.{name}", value=name,
                                  allowed="a curve name such as riIndexMCPy")
            if not abs(gain) <= MAX_GAIN:
                raise ConfigError("implausible gain", key=f"sources.{name}", value=gain,
                                  allowed=f"-{MAX_GAIN:g}..{MAX_GAIN:g} degrees per degree")
        low, high = self.range_deg
        if low >= high:
            raise ConfigError("inverted range: low must be below high", key="range_deg",
                              value=[low, high], allowed="[low, high] with low < high")


@dataclass(frozen=True)
class RetargetTable:
    """A retarget table file: ``[joints.<robot joint>]`` tables, in robot order."""

    format: Literal["handrig-retarget"]
    version: Literal[1]
    joints: dict[str, RetargetJoint]
    description: str = ""

    def check(self) -> None:
        if not self.joints:
            raise ConfigError("no robot joints", key="joints",
                              allowed="one [joints.<name>] table per robot joint")


@dataclass(frozen=True)
class Retarget:
    """A compiled retarget table: ``robot = clip(offset + gain @ human50, low, high)``.

    ``gain`` (J, 50), ``offset_deg``, ``low_deg``, ``high_deg`` (J,), rows in
    ``joint_names`` order.
    """

    joint_names: tuple[str, ...]
    gain: FloatArray
    offset_deg: FloatArray
    low_deg: FloatArray
    high_deg: FloatArray
    table: RetargetTable | None = None

    @classmethod
    def from_table(cls, table: RetargetTable) -> Retarget:
        names = tuple(table.joints)
        gain = np.zeros((len(names), len(hand.CURVE_NAMES)))
        for row, name in enumerate(names):
            for curve, g in table.joints[name].sources.items():
                gain[row, hand.curve_index(curve)] += g
        j = table.joints
        return cls(
            names, np.ascontiguousarray(gain),
            np.array([j[n].offset_deg for n in names], dtype=np.float64),
            np.array([j[n].range_deg[0] for n in names], dtype=np.float64),
            np.array([j[n].range_deg[1] for n in names], dtype=np.float64),
            table,
        )

    def index(self, joint: str) -> int:
        """Row of robot joint ``joint``; a :class:`KeyError` naming the known ones."""
        try:
            return self.joint_names.index(joint)
        except ValueError:
            raise KeyError(f"robot joint {joint!r} is not in the retarget table "
                           f"({', '.join(self.joint_names)})") from None

    def apply(self, human_deg: FloatArray, out: FloatArray | None = None) -> FloatArray:
        """One pose (50,) -> robot joints (J,), clipped to the robot's range."""
        h = np.asarray(human_deg, dtype=np.float64)
        if h.shape != (len(hand.CURVE_NAMES),):
            raise DataError(f"a human pose has {len(hand.CURVE_NAMES)} curves, got {h.shape}")
        if out is None:
            out = np.empty(len(self.joint_names))
        return retarget(h, self.gain, self.offset_deg, self.low_deg, self.high_deg, out)

    def unclipped_many(self, human_deg: FloatArray) -> FloatArray:
        """Many poses (n, 50) -> robot joints (n, J) before the clip (to see limit hits)."""
        h = np.asarray(human_deg, dtype=np.float64)
        if h.ndim != 2 or h.shape[1] != len(hand.CURVE_NAMES):
            raise DataError(f"expected (frames, {len(hand.CURVE_NAMES)}) poses, got {h.shape}")
        out: FloatArray = h @ self.gain.T + self.offset_deg
        return out

    def apply_many(self, human_deg: FloatArray) -> FloatArray:
        """Many poses (n, 50) -> robot joints (n, J), clipped."""
        out: FloatArray = np.clip(self.unclipped_many(human_deg), self.low_deg, self.high_deg)
        return out

    def source_interval_deg(self, human_low: FloatArray, human_high: FloatArray
                            ) -> tuple[FloatArray, FloatArray]:
        """The range each robot joint would take, unclipped, when every human curve
        may be anywhere in ``[human_low, human_high]`` (50,) (interval arithmetic)."""
        g = self.gain
        lo = self.offset_deg + np.where(g > 0, g * human_low, g * human_high).sum(axis=1)
        hi = self.offset_deg + np.where(g > 0, g * human_high, g * human_low).sum(axis=1)
        return lo, hi

    def check_against_model(self, joints: dict[str, MjcfJoint], *, file: str = "") -> None:
        """Every row names a hinge of the model and lies within its range (0.05 deg
        tolerance for rounding); a :class:`ConfigError` at ``joints.<name>`` otherwise."""
        for k, name in enumerate(self.joint_names):
            key = f"joints.{name}"
            j = joints.get(name)
            if j is None or j.type != "hinge":
                import difflib

                close = difflib.get_close_matches(name, list(joints), n=1)
                hint = f"did you mean {close[0]!r}? " if close else ""
                raise ConfigError("no such hinge joint in the robot model", file=file or None,
                                  key=key, value=name,
                                  allowed=f"{hint}one of {', '.join(joints)}")
            if j.range is not None:
                low, high = j.range
                rng = (float(self.low_deg[k]), float(self.high_deg[k]))
                if rng[0] < low - 0.05 or rng[1] > high + 0.05:
                    raise ConfigError(
                        "range exceeds the model's joint range", file=file or None,
                        key=f"{key}.range_deg", value=list(rng),
                        allowed=f"within [{low:.2f}, {high:.2f}] deg",
                    )


def retarget(human_deg: FloatArray, gain: FloatArray, offset_deg: FloatArray,
             low_deg: FloatArray, high_deg: FloatArray, out: FloatArray) -> FloatArray:
    """``out = clip(offset_deg + gain @ human_deg, low_deg, high_deg)``; no allocation."""
    np.dot(gain, human_deg, out=out)
    out += offset_deg
    np.clip(out, low_deg, high_deg, out=out)
    return out


def load_retarget(path: str | Path) -> Retarget:
    """Load and compile a retarget table; every problem is a ConfigError naming file and key."""
    return Retarget.from_table(load(path, RetargetTable))


@dataclass(frozen=True)
class JointCheck:
    """How one robot joint's inputs compare with its range (``handrig retarget check``).

    Ranges are of the unclipped retarget output, degrees; ``None`` when that data was
    not given. ``demo_low_frac`` / ``demo_high_frac``: share of demo frames whose
    output is clipped at the robot's low / high limit; :attr:`demo_cover_frac`: share
    of the robot's range the demo moves the joint through.
    """

    joint: str
    range_deg: tuple[float, float]
    anatomical_deg: tuple[float, float]
    capture_deg: tuple[float, float] | None
    demo_deg: tuple[float, float] | None
    demo_low_frac: float
    demo_high_frac: float

    @property
    def demo_cover_frac(self) -> float | None:
        """Share of the robot's range the demo's output covers (clipped to the range);
        ``None`` without demo data."""
        if self.demo_deg is None:
            return None
        low, high = self.range_deg
        covered = min(high, self.demo_deg[1]) - max(low, self.demo_deg[0])
        return max(0.0, covered) / (high - low) if high > low else 0.0

    @property
    def flags(self) -> tuple[str, ...]:
        """Which inputs reach past the robot's range: "capture", "demo", "anatomy"."""
        low, high = self.range_deg
        out = []
        for name, rng in (("capture", self.capture_deg), ("demo", self.demo_deg),
                          ("anatomy", self.anatomical_deg)):
            if rng is not None and (rng[0] < low or rng[1] > high):
                out.append(name)
        return tuple(out)


def check_joints(
    rt: Retarget,
    human_low_deg: FloatArray,
    human_high_deg: FloatArray,
    capture_deg: FloatArray | None = None,
    demo_deg: FloatArray | None = None,
) -> list[JointCheck]:
    """Per robot joint: the range its sources reach over the human limits (50,), the
    capture poses and the demo poses (n, 50), and how often the demo hits each limit."""
    a_lo, a_hi = rt.source_interval_deg(human_low_deg, human_high_deg)

    def span(poses: FloatArray | None) -> FloatArray | None:
        return None if poses is None or len(poses) == 0 else rt.unclipped_many(poses)

    cap, demo = span(capture_deg), span(demo_deg)
    out = []
    for k, name in enumerate(rt.joint_names):
        lo, hi = float(rt.low_deg[k]), float(rt.high_deg[k])
        low_frac = high_frac = 0.0
        if demo is not None:
            low_frac = float(np.mean(demo[:, k] < lo))
            high_frac = float(np.mean(demo[:, k] > hi))
        out.append(JointCheck(
            name, (lo, hi), (float(a_lo[k]), float(a_hi[k])),
            None if cap is None else (float(cap[:, k].min()), float(cap[:, k].max())),
            None if demo is None else (float(demo[:, k].min()), float(demo[:, k].max())),
            low_frac, high_frac,
        ))
    return out


def table_text(rt: Retarget, header: str, description: str = "") -> str:
    """``rt`` as a retarget table file (TOML): ``header`` as comment lines, then one
    ``[joints.<name>]`` table per row with its sources (curve order), offset, range and
    the note of the table it came from. Loading the text gives ``rt`` back."""
    notes = rt.table.joints if rt.table is not None else {}
    desc = description or (rt.table.description if rt.table is not None else "")
    lines = [f"# {ln}".rstrip() for ln in header.splitlines()]
    lines += ['format = "handrig-retarget"', "version = 1"]
    if desc:
        lines.append(f"description = {_toml_string(desc)}")
    for k, name in enumerate(rt.joint_names):
        sources = ", ".join(f"{hand.CURVE_NAMES[c]} = {rt.gain[k, c]:g}"
                            for c in np.nonzero(rt.gain[k])[0])
        key = name if name.replace("_", "").isalnum() else _toml_string(name)
        lines += ["", f"[joints.{key}]",
                  f"sources = {{ {sources} }}" if sources else "sources = {}",
                  f"offset_deg = {float(rt.offset_deg[k]) + 0.0:g}",
                  f"range_deg = [{float(rt.low_deg[k]):g}, {float(rt.high_deg[k]):g}]"]
        note = notes[name].note if name in notes else ""
        if note:
            lines.append(f"note = {_toml_string(note)}")
    return "\n".join(lines) + "\n"


def _toml_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'
