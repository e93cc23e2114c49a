"""An anthropometric two-hand skeleton for the outputs (VMC bone offsets, BVH hierarchy).

Segment lengths are fractions of hand length HL (Buchholz, Armstrong & Goldstein
1992, via REFERENCE.md section 4); MCP and thumb-CMC lateral offsets are fractions
of hand breadth HB from the third metacarpal axis (same table). Where the table is
silent the value is marked "assumed".

Directions are given in anatomical terms for a humanoid in T-pose with the palms
down: ``out`` points from the body along the arm (the hand's long axis, distal),
``up`` is the dorsal side of the hand, ``fwd`` is the way the avatar faces (the
radial, thumb side with palms down). Each output turns these into its own frame.
"""

from __future__ import annotations

from dataclasses import dataclass

from handrig.pose.hand_geometry import LATERAL_FRAC, SEGMENT_FRAC

HAND_LENGTH_M = 0.19
"""HL, wrist crease to middle fingertip (REFERENCE.md section 4)."""
HAND_BREADTH_M = 0.085
"""HB, across the MCP knuckles (REFERENCE.md section 4)."""
FOREARM_LENGTH_M = 0.26  # assumed: elbow to wrist, as the reference mocap skeleton (26 cm)

# digit -> (metacarpal, proximal, middle, distal) as fractions of HL; thumb has no middle
# (0 here). The numbers are the hand model's (handrig/pose/hand_geometry.py): one table.
SEGMENT_FRACTIONS: dict[str, tuple[float, float, float, float]] = {
    d: (m, p, mid if mid is not None else 0.0, dist)
    for d, (m, p, mid, dist) in SEGMENT_FRAC.items()
}
# Lateral offset of the MCP (thumb: CMC) from the third metacarpal axis, fraction of HB,
# radial positive.
LATERAL_FRACTIONS: dict[str, float] = dict(LATERAL_FRAC)
THUMB_CMC_DISTAL_FRACTION = 0.08  # assumed: CMC lies this far (x HL) distal of the wrist axis
THUMB_CMC_PALMAR_FRACTION = 0.1  # assumed: and this far (x HB) palmar of the knuckle plane


@dataclass(frozen=True)
class Anat:
    """A vector in anatomical components (out, up, fwd), see the module docstring."""

    out: float
    up: float
    fwd: float

    def scaled(self, k: float) -> Anat:
        return Anat(self.out * k, self.up * k, self.fwd * k)

    def norm(self) -> float:
        return float((self.out**2 + self.up**2 + self.fwd**2) ** 0.5)

    def unit(self) -> Anat:
        return self.scaled(1.0 / self.norm())


_S2 = 2.0**-0.5

# Digit directions at rest (T-pose, palm down). ``d`` distal, ``f`` where the tip goes
# when the joint flexes, ``b`` where it goes on positive (radial) abduction.
FINGER_DIRS = (Anat(1, 0, 0), Anat(0, -1, 0), Anat(0, 0, 1))
# The thumb points out and forward at 45 deg, its pad turned toward the index (the
# thumb column is rotated about 90 deg against the fingers): flexion carries the tip
# across the palm (ulnar and palmar), abduction away from the palm (palmar and radial).
THUMB_DIRS = (
    Anat(_S2, 0.0, _S2),
    Anat(0.5, -_S2, -0.5),
    Anat(-0.5, -_S2, 0.5),
)


def digit_dirs(digit: str) -> tuple[Anat, Anat, Anat]:
    """(distal, flexion, abduction) unit directions of ``digit`` at rest."""
    return THUMB_DIRS if digit == "Thumb" else FINGER_DIRS


def digit_offsets_m(digit: str, hl_m: float = HAND_LENGTH_M,
                    hb_m: float = HAND_BREADTH_M) -> tuple[Anat, Anat, Anat, Anat]:
    """Offsets of a digit's joints, each from its parent, in metres.

    Returns (root joint from the wrist, second from the root, third from the second,
    tip from the third). For fingers the root is the MCP; for the thumb the CMC,
    then MCP, IP and the tip.
    """
    mc, prox, mid, dist = (f * hl_m for f in SEGMENT_FRACTIONS[digit])
    lat = LATERAL_FRACTIONS[digit] * hb_m
    d = digit_dirs(digit)[0]
    if digit == "Thumb":
        root = Anat(THUMB_CMC_DISTAL_FRACTION * hl_m, -THUMB_CMC_PALMAR_FRACTION * hb_m, lat)
        return root, d.scaled(mc), d.scaled(prox), d.scaled(dist)
    return Anat(mc, 0.0, lat), d.scaled(prox), d.scaled(mid), d.scaled(dist)
