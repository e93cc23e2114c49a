"""The human hand model's bones: segment lengths, digit bases, joint axes (one source).

The numbers of the one hand every part of handrig poses: the MuJoCo hand of ``sim/``
(:mod:`sim.hand_model` builds its MJCF from :func:`hand_geometry` and
:func:`joint_axis`) and the OpenXR hand joints (:mod:`handrig.pose.openxr_hand`), so
the two cannot drift apart. Segment lengths are fractions of the hand length HL
(REFERENCE.md section 4, Buchholz et al. 1992), lateral offsets fractions of the hand
breadth HB; values the table is silent on are marked "assumed".

Frames (see :mod:`sim.hand_model` for the whole model): the **forearm frame** has x
distal along the forearm, z dorsal, y = z x x (radial for the right hand); the left
hand is the mirror image (positions y -> -y, joint axes (ax, ay, az) -> (-ax, ay, -az)),
so its y points ulnar and the frame stays right-handed. The wrist axis is the origin;
digit bases sit ``CARPUS_FRAC`` x HL distal of it, so wrist-to-middle-fingertip = HL.
At zero joint angles every body frame is axis-aligned with the forearm frame and every
digit points along +x.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from handrig.hand import DIGITS, Hand

DENSITY_KG_M3 = 1100.0  # REFERENCE.md section 4: cylinders at 1.1 g/cm^3
REFERENCE_HAND_LENGTH_M = 0.19
HAND_MASS_KG = 0.45  # about 0.6 % of body mass at HL 0.19 m (REFERENCE.md)
HAND_COM_FRAC = 0.506  # of wrist axis -> middle MCP (REFERENCE.md)
BREADTH_PER_LENGTH = 0.085 / 0.19  # HB about 0.085 m at HL 0.19 m
CARPUS_FRAC = 1.0 - (0.373 + 0.266 + 0.170 + 0.108)  # wrist axis -> digit bases, of HL

# Segment lengths as fractions of HL: metacarpal, proximal, middle, distal
# (REFERENCE.md section 4; the thumb has no middle phalanx).
SEGMENT_FRAC: dict[str, tuple[float, float, float | None, float]] = {
    "Thumb": (0.251, 0.196, None, 0.158),
    "Index": (0.374, 0.245, 0.143, 0.097),
    "Middle": (0.373, 0.266, 0.170, 0.108),
    "Ring": (0.336, 0.244, 0.165, 0.107),
    "Pinky": (0.295, 0.204, 0.117, 0.093),
}
# Phalanx masses in grams at HL 0.19 m: proximal, middle, distal.
PHALANX_MASS_G: dict[str, tuple[float, float | None, float]] = {
    "Thumb": (12.2, None, 8.4),
    "Index": (15.2, 6.6, 3.5),
    "Middle": (14.7, 7.8, 4.1),
    "Ring": (11.9, 6.5, 3.6),
    "Pinky": (8.1, 3.8, 2.4),
}
# MCP lateral offsets from the third metacarpal axis, fractions of HB, radial positive.
LATERAL_FRAC: dict[str, float] = {
    "Thumb": 0.196, "Index": 0.126, "Middle": 0.0, "Ring": -0.129, "Pinky": -0.223,
}
THUMB_CMC_PALMAR_FRAC = 0.08  # thumb CMC sits palmar of the palm mid-plane, of HL (assumed)
PALM_THICKNESS_FRAC = 0.15  # of HL (assumed, for the palm's inertia only)

THUMB_FLEX_TILT_DEG = 30.0  # thumb MCP/IP flexion axis tilt from the palm normal (assumed)
_SB = math.sin(math.radians(THUMB_FLEX_TILT_DEG))
_CB = math.cos(math.radians(THUMB_FLEX_TILT_DEG))
# Joint axes in the right hand's forearm frame (bodies are axis-aligned at zero).
JOINT_AXES_RI: dict[str, tuple[float, float, float]] = {
    "WristFlexion": (0.0, 1.0, 0.0),
    "WristDeviation": (0.0, 0.0, 1.0),
    "FingerMCPx": (0.0, 0.0, 1.0),
    "FingerFlex": (0.0, 1.0, 0.0),
    "ThumbCMCy": (0.0, 0.0, 1.0),
    "ThumbCMCz": (0.0, 1.0, 0.0),
    "ThumbFlex": (0.0, _SB, -_CB),
    "ThumbCMCx": (-1.0, 0.0, 0.0),
}


@dataclass(frozen=True)
class Segment:
    """One rigid segment of the model: the body it belongs to, its length and mass."""

    body: str
    length_m: float
    mass_kg: float
    radius_m: float


@dataclass(frozen=True)
class HandGeometry:
    """Lengths, masses and positions for one hand length (right hand, forearm frame)."""

    hand_length_m: float
    breadth_m: float
    segments: dict[str, list[Segment]] = field(default_factory=dict)
    base_pos_m: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    palm_mass_kg: float = 0.0
    palm_com_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    palm_size_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def total_mass_kg(self) -> float:
        return self.palm_mass_kg + sum(s.mass_kg for segs in self.segments.values() for s in segs)


def _radius(mass_kg: float, length_m: float) -> float:
    return math.sqrt(mass_kg / (DENSITY_KG_M3 * math.pi * length_m))


def hand_geometry(hand_length_m: float = REFERENCE_HAND_LENGTH_M) -> HandGeometry:
    """Segment lengths and masses scaled from the anthropometric table to ``hand_length_m``."""
    if not (0.10 <= hand_length_m <= 0.30):
        raise ValueError(f"hand_length_m={hand_length_m} outside 0.10..0.30 m (adult ~0.19 m)")
    hl = hand_length_m
    hb = BREADTH_PER_LENGTH * hl
    mscale = (hl / REFERENCE_HAND_LENGTH_M) ** 3
    segments: dict[str, list[Segment]] = {}
    base: dict[str, tuple[float, float, float]] = {}
    for digit in DIGITS:
        meta, prox, mid, dist = SEGMENT_FRAC[digit]
        mp, mm, md = PHALANX_MASS_G[digit]
        segs: list[Segment] = []
        if digit == "Thumb":
            lp = prox * hl
            r_p = _radius(mp * 1e-3 * mscale, lp)
            lmc = meta * hl
            m_mc = DENSITY_KG_M3 * math.pi * r_p**2 * lmc
            segs.append(Segment("CMC", lmc, m_mc, r_p))
            segs.append(Segment("MCP", lp, mp * 1e-3 * mscale, r_p))
            ld = dist * hl
            segs.append(Segment("IP", ld, md * 1e-3 * mscale, _radius(md * 1e-3 * mscale, ld)))
            base[digit] = (CARPUS_FRAC * hl, LATERAL_FRAC[digit] * hb, -THUMB_CMC_PALMAR_FRAC * hl)
        else:
            assert mid is not None and mm is not None  # fingers have a middle phalanx
            for body, frac, mass_g in (("MCP", prox, mp), ("PIP", mid, mm), ("DIP", dist, md)):
                length, mass = frac * hl, mass_g * 1e-3 * mscale
                segs.append(Segment(body, length, mass, _radius(mass, length)))
            base[digit] = ((CARPUS_FRAC + meta) * hl, LATERAL_FRAC[digit] * hb, 0.0)
        segments[digit] = segs
    digit_mass = sum(s.mass_kg for segs in segments.values() for s in segs)
    total = HAND_MASS_KG * mscale
    palm_mass = total - digit_mass
    # Straight hand: centre of mass at HAND_COM_FRAC of wrist -> middle MCP.
    moment = 0.0
    for digit, segs in segments.items():
        x = base[digit][0]
        for s in segs:
            moment += s.mass_kg * (x + s.length_m / 2)
            x += s.length_m
    d_mcp3 = base["Middle"][0]
    palm_x = (HAND_COM_FRAC * d_mcp3 * total - moment) / palm_mass
    return HandGeometry(
        hand_length_m=hl, breadth_m=hb, segments=segments, base_pos_m=base,
        palm_mass_kg=palm_mass, palm_com_m=(palm_x, 0.0, 0.0),
        palm_size_m=(d_mcp3, hb, PALM_THICKNESS_FRAC * hl),
    )


def mirror_pos(p: Sequence[float], hand: Hand) -> tuple[float, float, float]:
    return (p[0], -p[1], p[2]) if hand == "le" else (p[0], p[1], p[2])


def mirror_axis(a: Sequence[float], hand: Hand) -> tuple[float, float, float]:
    # A rotation axis is a pseudovector: under y -> -y it maps to (-ax, ay, -az).
    return (-a[0], a[1], -a[2]) if hand == "le" else (a[0], a[1], a[2])


def joint_axis(name: str, hand: Hand = "ri") -> tuple[float, float, float]:
    """The joint axis of DOF ``name`` (e.g. ``riIndexMCPy``) in its body frame."""
    stem = name[2:]
    if stem in ("WristFlexion", "WristDeviation"):
        key = stem
    elif stem.startswith("Thumb"):
        key = {"CMCx": "ThumbCMCx", "CMCy": "ThumbCMCy", "CMCz": "ThumbCMCz"}.get(
            stem[5:], "ThumbFlex")
    else:
        key = "FingerMCPx" if stem.endswith("MCPx") else "FingerFlex"
    return mirror_axis(JOINT_AXES_RI[key], hand)
