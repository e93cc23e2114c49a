"""Hinge and slide joints of an MJCF model, read as XML (no MuJoCo needed).

Rig files and retarget tables name a robot's joints and give their ranges; this
module reads the model those names must agree with. It resolves what a range
check needs: ``<compiler angle>`` (MuJoCo's default is degrees), ``<default>``
classes (nested, inherited), ``class`` on a joint and ``childclass`` on bodies.
``<include>`` is not followed. Ranges are returned in degrees for hinges and in
metres for slides. MuJoCo's own compiler is what the simulation uses; the tests
check that the two agree on the shipped models.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from handrig.errors import ConfigError


@dataclass(frozen=True)
class MjcfJoint:
    """One joint of the model: name, type, and its range (None when unlimited)."""

    name: str
    type: str  # "hinge" or "slide"
    range: tuple[float, float] | None  # degrees for a hinge, metres for a slide


def _parse_range(text: str, file: str, where: str) -> tuple[float, float]:
    parts = text.split()
    try:
        low, high = (float(p) for p in parts)
    except ValueError:
        raise ConfigError(f"joint range {text!r} is not two numbers ({where})", file=file) from None
    return low, high


def _defaults(root: ET.Element) -> dict[str, dict[str, str]]:
    """Joint attributes of every default class, inheritance applied ("main" = top)."""
    out: dict[str, dict[str, str]] = {}

    def walk(node: ET.Element, inherited: dict[str, str], name: str) -> None:
        attrs = dict(inherited)
        joint = node.find("joint")
        if joint is not None:
            attrs.update(joint.attrib)
        out[name] = attrs
        for child in node.findall("default"):
            walk(child, attrs, child.get("class", "main"))

    for top in root.findall("default"):
        walk(top, {}, top.get("class", "main"))
    return out


def read_joints(path: str | Path) -> dict[str, MjcfJoint]:
    """The model's named hinge and slide joints, in document order.

    A missing or malformed file is a :class:`ConfigError` naming it.
    """
    p = Path(path)
    try:
        root = ET.parse(p).getroot()
    except FileNotFoundError:
        raise ConfigError("MJCF model not found", file=str(p)) from None
    except (OSError, ET.ParseError) as exc:
        raise ConfigError(f"cannot read the MJCF model: {exc}", file=str(p)) from None
    if root.tag != "mujoco":
        raise ConfigError(f"not an MJCF model (root element <{root.tag}>)", file=str(p))
    compiler = root.find("compiler")
    in_degrees = compiler is None or compiler.get("angle", "degree") == "degree"
    defaults = _defaults(root)
    joints: dict[str, MjcfJoint] = {}

    def walk(body: ET.Element, childclass: str) -> None:
        cls_here = body.get("childclass", childclass)
        for joint in body.findall("joint"):
            attrs = dict(defaults.get(joint.get("class", cls_here), defaults.get("main", {})))
            attrs.update(joint.attrib)
            name = attrs.get("name")
            jtype = attrs.get("type", "hinge")
            if not name or jtype not in ("hinge", "slide"):
                continue
            limited = attrs.get("limited", "auto")
            rng: tuple[float, float] | None = None
            if "range" in attrs and limited != "false":
                low, high = _parse_range(attrs["range"], str(p), f"joint {name}")
                if jtype == "hinge" and not in_degrees:
                    low, high = math.degrees(low), math.degrees(high)
                rng = (low, high)
            joints[name] = MjcfJoint(name, jtype, rng)
        for child in body.findall("body"):
            walk(child, cls_here)

    for world in root.findall("worldbody"):
        for body in world.findall("body"):
            walk(body, body.get("childclass", "main"))
    return joints
