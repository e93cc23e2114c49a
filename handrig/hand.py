"""The hand vocabulary: curve and DOF names, order, axes, limits and mirroring.

Two name sets, one spelling:

* the **50 rotation curves** of Jörg & O'Sullivan, "Exploring the Dimensionality
  of Finger Motion" (section 3): ``ri``/``le`` + digit + joint + axis letter,
  25 per hand. Thumb: ``CMCx CMCy CMCz MCPz IPz``; fingers: ``MCPx MCPy MCPz
  PIPy DIPy``. The paper: fingers flex about y and spread about x; the thumb,
  "rotated by 90 degrees", flexes about z. So for fingers x = abduction,
  y = flexion, z = twist, and for the thumb z = flexion, y = abduction,
  x = twist (axial rotation of the CMC).
* the **23 DOFs** of Neff & Seidel, "Modeling Relaxed Hand Shape" (section 3),
  for one hand: finger MCP flexion and abduction, PIP, DIP; thumb CMC (3), MCP,
  IP; wrist flexion and deviation. Digit DOFs reuse the curve names; the wrist
  DOFs are ``riWristFlexion`` and ``riWristDeviation``. Finger ``MCPz`` (twist)
  has no DOF in that model; the wrist has no curve in the first paper.

Sign convention (the "vocabulary convention" used by every pose in handrig):
flexion positive; abduction and wrist deviation positive toward the thumb
(radial), so ulnar deviation and spreading the little finger away are negative;
twist positive = pronation-like rotation of the digit. Both hands use the same
anatomical convention, so mirroring a pose swaps the ``ri``/``le`` halves and
keeps every value.
"""

from __future__ import annotations

import difflib
import enum
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from handrig.errors import HandrigError

Hand = Literal["ri", "le"]
HANDS: tuple[Hand, Hand] = ("ri", "le")
DIGITS: tuple[str, ...] = ("Thumb", "Index", "Middle", "Ring", "Pinky")
FINGERS: tuple[str, ...] = DIGITS[1:]
THUMB_JOINTS: tuple[tuple[str, str], ...] = (
    ("CMC", "x"), ("CMC", "y"), ("CMC", "z"), ("MCP", "z"), ("IP", "z"),
)
FINGER_JOINTS: tuple[tuple[str, str], ...] = (
    ("MCP", "x"), ("MCP", "y"), ("MCP", "z"), ("PIP", "y"), ("DIP", "y"),
)


class Motion(enum.Enum):
    """What an axis does anatomically."""

    FLEXION = "flexion"
    ABDUCTION = "abduction"
    TWIST = "twist"


def motion_of(digit: str, joint: str, axis: str) -> Motion:
    """Which anatomical motion ``axis`` of ``joint`` on ``digit`` is."""
    if digit == "Thumb":
        table = {"z": Motion.FLEXION, "y": Motion.ABDUCTION, "x": Motion.TWIST}
    elif digit in FINGERS:
        table = {"y": Motion.FLEXION, "x": Motion.ABDUCTION, "z": Motion.TWIST}
    elif digit == "Wrist":
        return Motion.FLEXION if joint == "Flexion" else Motion.ABDUCTION
    else:
        raise UnknownJointError(f"unknown digit {digit!r}; digits are {', '.join(DIGITS)}")
    return table[axis]


class UnknownJointError(HandrigError, KeyError):
    """A curve or DOF name that the vocabulary does not know."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else "unknown joint"


@dataclass(frozen=True)
class Curve:
    """One rotation curve of the finger-dimensionality paper, e.g. ``riIndexMCPy``."""

    hand: Hand
    digit: str
    joint: str
    axis: str
    index: int

    @property
    def name(self) -> str:
        return f"{self.hand}{self.digit}{self.joint}{self.axis}"

    @property
    def motion(self) -> Motion:
        return motion_of(self.digit, self.joint, self.axis)


def _build_curves() -> tuple[Curve, ...]:
    out: list[Curve] = []
    for hand in HANDS:
        for digit in DIGITS:
            joints = THUMB_JOINTS if digit == "Thumb" else FINGER_JOINTS
            for joint, axis in joints:
                out.append(Curve(hand, digit, joint, axis, len(out)))
    return tuple(out)


CURVES: tuple[Curve, ...] = _build_curves()
"""The 50 curves in canonical order: right hand then left, thumb to pinky, joint order as named."""
CURVE_NAMES: tuple[str, ...] = tuple(c.name for c in CURVES)
CURVES_PER_HAND = 25
_CURVE_BY_NAME = {c.name: c for c in CURVES}


@dataclass(frozen=True)
class Dof:
    """One DOF of the relaxed-hand model for one hand (``riPinkyPIPy``, ``riWristFlexion``)."""

    name: str
    hand: Hand
    digit: str  # "Wrist" for the two wrist DOFs
    joint: str  # "CMC", "MCP", "PIP", "DIP", "IP", or "Flexion"/"Deviation" for the wrist
    axis: str  # axis letter, "" for the wrist
    index: int  # position in the per-hand DOF order (0..22)
    curve: str | None  # the curve it shares a name with; None for the wrist

    @property
    def motion(self) -> Motion:
        return motion_of(self.digit, self.joint, self.axis)


_FINGER_DOF_JOINTS: tuple[tuple[str, str], ...] = (
    ("MCP", "y"), ("MCP", "x"), ("PIP", "y"), ("DIP", "y"),
)


def _build_dofs(hand: Hand) -> tuple[Dof, ...]:
    out: list[Dof] = []
    for digit in DIGITS:
        joints = THUMB_JOINTS if digit == "Thumb" else _FINGER_DOF_JOINTS
        for joint, axis in joints:
            name = f"{hand}{digit}{joint}{axis}"
            out.append(Dof(name, hand, digit, joint, axis, len(out), name))
    for joint in ("Flexion", "Deviation"):
        out.append(Dof(f"{hand}Wrist{joint}", hand, "Wrist", joint, "", len(out), None))
    return tuple(out)


DOFS: dict[Hand, tuple[Dof, ...]] = {h: _build_dofs(h) for h in HANDS}
"""The 23 relaxed-hand DOFs per hand, in model order: thumb, index..pinky, wrist."""
DOFS_PER_HAND = 23
DOF_NAMES: dict[Hand, tuple[str, ...]] = {h: tuple(d.name for d in DOFS[h]) for h in HANDS}
_DOF_BY_NAME = {d.name: d for h in HANDS for d in DOFS[h]}
ALL_JOINT_NAMES: tuple[str, ...] = CURVE_NAMES + tuple(
    d.name for h in HANDS for d in DOFS[h] if d.curve is None
)
"""Every name a limit or a servo can refer to: the 50 curves plus the 4 wrist DOFs."""


def _suggest(name: str) -> str:
    close = difflib.get_close_matches(name, ALL_JOINT_NAMES, n=1)
    return f"; did you mean {close[0]!r}?" if close else ""


def curve(name: str) -> Curve:
    """The curve called ``name``; :class:`UnknownJointError` with a suggestion otherwise."""
    try:
        return _CURVE_BY_NAME[name]
    except KeyError:
        raise UnknownJointError(
            f"unknown curve {name!r}: curves are ri/le + Thumb/Index/Middle/Ring/Pinky"
            f" + joint + axis, e.g. riIndexMCPy{_suggest(name)}"
        ) from None


def curve_index(name: str) -> int:
    """Position of curve ``name`` in :data:`CURVE_NAMES`."""
    return curve(name).index


def dof(name: str) -> Dof:
    """The relaxed-hand DOF called ``name``."""
    try:
        return _DOF_BY_NAME[name]
    except KeyError:
        raise UnknownJointError(
            f"unknown DOF {name!r}: DOFs are the digit curves without finger MCPz, plus"
            f" riWristFlexion/riWristDeviation (le... for the left hand){_suggest(name)}"
        ) from None


def is_joint_name(name: str) -> bool:
    """True for any curve or DOF name."""
    return name in _CURVE_BY_NAME or name in _DOF_BY_NAME


def select_curves(
    hand: Hand | None = None,
    digit: str | None = None,
    joint: str | None = None,
    axis: str | None = None,
    motion: Motion | None = None,
) -> tuple[Curve, ...]:
    """Curves matching every criterion given, in canonical order."""
    if digit is not None and digit not in DIGITS:
        raise UnknownJointError(f"unknown digit {digit!r}; digits are {', '.join(DIGITS)}")
    return tuple(
        c
        for c in CURVES
        if (hand is None or c.hand == hand)
        and (digit is None or c.digit == digit)
        and (joint is None or c.joint == joint)
        and (axis is None or c.axis == axis)
        and (motion is None or c.motion == motion)
    )


def dof_curve_indices(hand: Hand) -> NDArray[np.intp]:
    """For each of the 23 DOFs of ``hand``, the index of its curve in the 50, or -1 (wrist)."""
    return np.array(
        [curve_index(d.curve) if d.curve else -1 for d in DOFS[hand]], dtype=np.intp
    )


# Anatomical ranges in degrees, vocabulary convention (flexion and radial positive).
# Sources: typical active ranges of motion of the wrist, finger and thumb joints from the
# clinical anthropometry literature (as collected for the Sancho-Bru / Buchholz hand
# models). Marked "assumed" where no range was found: conservative guesses, not data.
_RANGE_BY_KIND: dict[tuple[str, str, str], tuple[float, float]] = {
    ("Thumb", "CMC", "x"): (-20.0, 40.0),  # assumed: axial rotation (opposition)
    ("Thumb", "CMC", "y"): (-30.0, 60.0),  # abduction
    ("Thumb", "CMC", "z"): (-25.0, 35.0),  # flexion
    ("Thumb", "MCP", "z"): (-10.0, 55.0),
    ("Thumb", "IP", "z"): (-15.0, 80.0),
    ("Finger", "MCP", "x"): (-20.0, 20.0),
    ("Finger", "MCP", "y"): (-20.0, 90.0),
    ("Finger", "MCP", "z"): (-15.0, 15.0),  # assumed: passive axial twist
    ("Finger", "PIP", "y"): (0.0, 110.0),
    ("Finger", "DIP", "y"): (-10.0, 90.0),
    ("Wrist", "Flexion", ""): (-70.0, 80.0),
    ("Wrist", "Deviation", ""): (-30.0, 20.0),  # ulnar negative, radial positive
}


def _kind(digit: str) -> str:
    return digit if digit in ("Thumb", "Wrist") else "Finger"


def anatomical_limits_deg(name: str) -> tuple[float, float]:
    """(low, high) in degrees for any curve or DOF name, vocabulary convention."""
    if name in _CURVE_BY_NAME:
        c = _CURVE_BY_NAME[name]
        return _RANGE_BY_KIND[(_kind(c.digit), c.joint, c.axis)]
    d = dof(name)
    return _RANGE_BY_KIND[(_kind(d.digit), d.joint, d.axis)]


def curve_limits_deg() -> NDArray[np.float64]:
    """A (50, 2) array of (low, high) per curve, in canonical order."""
    return np.array([anatomical_limits_deg(n) for n in CURVE_NAMES], dtype=np.float64)


def dof_limits_deg(hand: Hand = "ri") -> NDArray[np.float64]:
    """A (23, 2) array of (low, high) per DOF of ``hand``, in model order."""
    return np.array([anatomical_limits_deg(n) for n in DOF_NAMES[hand]], dtype=np.float64)


def mirror_name(name: str) -> str:
    """The same joint on the other hand: ``riIndexMCPy`` <-> ``leIndexMCPy``."""
    if not is_joint_name(name):
        curve(name)  # raises with a suggestion
    other = "le" if name.startswith("ri") else "ri"
    return other + name[2:]


def hand_of(name: str) -> Hand:
    """``"ri"`` or ``"le"`` for a curve or DOF name."""
    if not is_joint_name(name):
        curve(name)
    return "ri" if name.startswith("ri") else "le"


_MIRROR_PERMUTATION = np.array([curve_index(mirror_name(n)) for n in CURVE_NAMES], dtype=np.intp)


def mirror_pose(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Mirror a pose (..., 50) in the vocabulary convention: swap the hands, keep values."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.shape[-1] != len(CURVES):
        raise ValueError(f"a pose has {len(CURVES)} curves on its last axis, got {arr.shape}")
    return arr[..., _MIRROR_PERMUTATION]
