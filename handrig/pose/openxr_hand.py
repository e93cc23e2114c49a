"""The operator's hand as the 26 OpenXR hand joints (XR_EXT_hand_tracking), from a pose.

For peers that speak a tracked human hand rather than a robot's joints (an OpenXR
application, Isaac Teleop's hand trackers): one hand's 25 curves (degrees, the
vocabulary convention of :mod:`handrig.hand`) and its two wrist angles become the 26
joints of ``XrHandJointEXT``, each a pose (position in metres, orientation as a unit
quaternion x, y, z, w) and a radius in metres, by forward kinematics on the bones of
:mod:`handrig.pose.hand_geometry` (the MuJoCo hand of ``sim/`` is built from the same
numbers and joint axes; ``tests/sim/test_openxr_model_agrees.py`` checks the two agree).

Order and names (:data:`JOINT_NAMES`, ``XR_HAND_JOINT_<name>_EXT``): PALM 0, WRIST 1,
THUMB METACARPAL PROXIMAL DISTAL TIP 2-5, then INDEX, MIDDLE, RING and LITTLE, each
METACARPAL PROXIMAL INTERMEDIATE DISTAL TIP (6-10, 11-15, 16-20, 21-25).

Space and frames, as OpenXR has them: right-handed, +Y up, -Z forward, metres. A joint's
position is the base of the bone it names (a tip: the end of the distal bone); its
orientation has -Z along that bone toward the fingertip, +Y out of the back of the hand
(the nail) and X = Y x Z, so X points from the thumb toward the little finger on a
right hand and the other way on a left one. PALM sits at the middle of the middle
finger's metacarpal, WRIST on the wrist axis, both oriented with the hand.

Where the hand is: ``forearm`` is an :class:`XrPose` of the wrist axis with the
forearm's orientation; identity (the default) is the forearm pointing forward (-Z), the
back of the hand up (+Y). The wrist angles (flexion, deviation) turn the hand from
there, as the MuJoCo hand's wrist joints do. The glove measures no position, so a
stream places each wrist where its caller says (:mod:`handrig.outputs.openxr`).

The model's joints, in its own order: finger MCP abduction, flexion, then the twist
(``MCPz``, about the proximal bone's long axis; the MuJoCo hand has no joint for it, so
the agreement test holds twist at 0), PIP, DIP; thumb CMC abduction, flexion, twist,
then MCP and IP flexion about their tilted axis. Finger metacarpals are fixed in the
palm (the 25 curves have no palm arch). Radii are the model's segment cylinders
(from the phalanx masses); the palm's and the wrist's half the palm's thickness.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from handrig import hand as vocab
from handrig.errors import DataError
from handrig.hand import FINGERS, Hand
from handrig.pose import chain_kernel
from handrig.pose.hand_geometry import (
    CARPUS_FRAC,
    JOINT_AXES_RI,
    PALM_THICKNESS_FRAC,
    REFERENCE_HAND_LENGTH_M,
    SEGMENT_FRAC,
    hand_geometry,
    mirror_axis,
    mirror_pos,
)

FloatArray = NDArray[np.float64]

JOINT_COUNT = 26
"""XR_HAND_JOINT_COUNT_EXT."""
_DIGIT_XR = {"Thumb": "THUMB", "Index": "INDEX", "Middle": "MIDDLE", "Ring": "RING",
             "Pinky": "LITTLE"}
JOINT_NAMES: tuple[str, ...] = (
    "PALM", "WRIST",
    *(f"THUMB_{b}" for b in ("METACARPAL", "PROXIMAL", "DISTAL", "TIP")),
    *(f"{_DIGIT_XR[d]}_{b}" for d in FINGERS
      for b in ("METACARPAL", "PROXIMAL", "INTERMEDIATE", "DISTAL", "TIP")),
)
"""The 26 joints in ``XrHandJointEXT`` order, without the ``XR_HAND_JOINT_``/``_EXT``."""
XR_JOINT_NAMES: tuple[str, ...] = tuple(f"XR_HAND_JOINT_{n}_EXT" for n in JOINT_NAMES)
"""The enumerant names of ``XrHandJointEXT``, index = value."""
PALM, WRIST = 0, 1
THUMB_FIRST = 2  # THUMB_METACARPAL; then PROXIMAL, DISTAL, TIP
FINGER_FIRST = (6, 11, 16, 21)  # each finger's METACARPAL; then PROXIMAL .. TIP
TIPS = (5, 10, 15, 20, 25)
"""The tip joints, thumb to little finger."""
POSE_COLUMNS = ("px_m", "py_m", "pz_m", "qx", "qy", "qz", "qw")
"""A row of :attr:`HandJoints.poses`: position (metres), then the quaternion x, y, z, w."""

# The model's forearm frame (x distal, y radial on the right hand / ulnar on the left,
# z dorsal) in OpenXR axes, for the forearm's identity pose (pointing -Z, back up +Y):
# columns are the model's x, y, z. The same for both hands (the left hand's model frame
# is the right's mirror image with y ulnar, so its thumb lands on +X).
MODEL_TO_XR: FloatArray = np.array([[0.0, -1.0, 0.0],
                                    [0.0, 0.0, 1.0],
                                    [-1.0, 0.0, 0.0]])
# A body frame axis-aligned with the model frame is the OpenXR joint frame of a straight
# hand (-Z distal, +Y dorsal): a joint's orientation is MODEL_TO_XR R_body MODEL_TO_XR^T.

_FINGER_TWIST_AXIS = "ThumbCMCx"  # the vocabulary's twist is pronation-like on every digit
_N_ANGLES = 27  # wrist 2, thumb 5, fingers 4 x 5


@dataclass(frozen=True)
class XrPose:
    """A pose in OpenXR space: position (metres) and orientation (x, y, z, w)."""

    position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation_xyzw: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    def __post_init__(self) -> None:
        q = np.asarray(self.orientation_xyzw, dtype=np.float64)
        p = np.asarray(self.position_m, dtype=np.float64)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise DataError(f"a position is 3 finite numbers in metres, got {self.position_m!r}")
        norm = float(np.linalg.norm(q)) if q.shape == (4,) else 0.0
        if not np.isfinite(norm) or abs(norm - 1.0) > 1e-3:
            raise DataError(
                f"an orientation is a unit quaternion (x, y, z, w), got "
                f"{self.orientation_xyzw!r}: normalise it (identity is (0, 0, 0, 1))")

    def matrix(self) -> FloatArray:
        """The orientation as a 3 x 3 rotation matrix."""
        out: FloatArray = Rotation.from_quat(self.orientation_xyzw).as_matrix()
        return out


@dataclass(frozen=True)
class HandJoints:
    """One hand's 26 OpenXR joints. ``poses`` (26, 7): :data:`POSE_COLUMNS` per joint in
    :data:`JOINT_NAMES` order; ``radii_m`` (26,); ``hand`` ``"ri"`` or ``"le"``."""

    hand: Hand
    poses: FloatArray
    radii_m: FloatArray
    names: tuple[str, ...] = field(default=JOINT_NAMES)

    @property
    def positions_m(self) -> FloatArray:
        """(26, 3) joint positions, metres."""
        return self.poses[:, :3]

    @property
    def orientations_xyzw(self) -> FloatArray:
        """(26, 4) joint orientations, unit quaternions (x, y, z, w)."""
        return self.poses[:, 3:]

    def joint(self, name: str) -> FloatArray:
        """The (7,) pose of joint ``name`` (``INDEX_TIP`` or ``XR_HAND_JOINT_INDEX_TIP_EXT``)."""
        short = name.removeprefix("XR_HAND_JOINT_").removesuffix("_EXT")
        if short not in JOINT_NAMES:
            raise DataError(f"unknown OpenXR hand joint {name!r}: the joints are "
                            f"{', '.join(JOINT_NAMES)}")
        row: FloatArray = self.poses[JOINT_NAMES.index(short)]
        return row


class OpenXrHand:
    """The forward kinematics of one hand (side and length fixed), reusable per frame.

    :meth:`compute` writes one frame into a caller's buffer in one compiled step
    (:func:`handrig.pose.chain_kernel.chain_poses` over this hand's body tree);
    :func:`hand_joints` is the one-call form. ``hand_length_m``: HL, wrist crease to the
    middle fingertip.
    """

    def __init__(self, hand: Hand = "ri", hand_length_m: float = REFERENCE_HAND_LENGTH_M
                 ) -> None:
        if hand not in vocab.HANDS:
            raise DataError(f"hand must be 'ri' or 'le', got {hand!r}")
        if not 0.10 <= hand_length_m <= 0.30:
            raise DataError(f"hand length {hand_length_m} m outside 0.10..0.30 m (an adult's"
                            " is about 0.19 m)")
        self.hand: Hand = hand
        self.hand_length_m = float(hand_length_m)
        geo = hand_geometry(hand_length_m)
        hl = hand_length_m

        def axis(key: str) -> tuple[float, float, float]:
            return mirror_axis(JOINT_AXES_RI[key], hand)

        # hinges: wrist 0-1, thumb 2-6 (CMC abduction, flexion, twist, MCP, IP), then per
        # finger MCP abduction, flexion, twist, PIP, DIP
        finger_axes = [axis("FingerMCPx"), axis("FingerFlex"), axis(_FINGER_TWIST_AXIS),
                       axis("FingerFlex"), axis("FingerFlex")]
        self._axes = np.array([axis("WristFlexion"), axis("WristDeviation"),
                               axis("ThumbCMCy"), axis("ThumbCMCz"), axis("ThumbCMCx"),
                               axis("ThumbFlex"), axis("ThumbFlex"),
                               *(finger_axes * len(FINGERS))], dtype=np.float64)
        # the 25 curves (thumb CMCx CMCy CMCz MCPz IPz; fingers MCPx MCPy MCPz PIPy DIPy)
        # -> the hinges from 2 on
        self._curve_slot = np.array([1, 2, 0, 3, 4, *range(5, 25)], dtype=np.intp)
        # bodies: the hand, thumb CMC MCP IP, then per finger MCP PIP DIP
        thumb = geo.segments["Thumb"]
        parent: list[int] = [-1, 0, 1, 2]
        offset: list[Sequence[float]] = [
            (0.0, 0.0, 0.0), mirror_pos(geo.base_pos_m["Thumb"], hand),
            (thumb[0].length_m, 0.0, 0.0), (thumb[1].length_m, 0.0, 0.0)]
        joints: list[tuple[int, int, int]] = [(0, 1, -1), (2, 3, 4), (5, -1, -1), (6, -1, -1)]
        # points: (body, offset in it) per OpenXR joint
        middle_meta = SEGMENT_FRAC["Middle"][0] * hl
        points: list[tuple[int, Sequence[float]]] = [
            (0, (CARPUS_FRAC * hl + middle_meta / 2, 0.0, 0.0)), (0, (0.0, 0.0, 0.0)),
            (1, (0.0, 0.0, 0.0)), (2, (0.0, 0.0, 0.0)), (3, (0.0, 0.0, 0.0)),
            (3, (thumb[2].length_m, 0.0, 0.0))]
        radii = [PALM_THICKNESS_FRAC * hl / 2] * 2 + [thumb[0].radius_m, thumb[1].radius_m,
                                                       thumb[2].radius_m, thumb[2].radius_m]
        for f, digit in enumerate(FINGERS):
            segs = geo.segments[digit]
            mcp = mirror_pos(geo.base_pos_m[digit], hand)
            first, hinge = len(parent), 7 + 5 * f
            parent += [0, first, first + 1]
            offset += [mcp, (segs[0].length_m, 0.0, 0.0), (segs[1].length_m, 0.0, 0.0)]
            joints += [(hinge, hinge + 1, hinge + 2), (hinge + 3, -1, -1), (hinge + 4, -1, -1)]
            points += [(0, (CARPUS_FRAC * hl, mcp[1], mcp[2])), (first, (0.0, 0.0, 0.0)),
                       (first + 1, (0.0, 0.0, 0.0)), (first + 2, (0.0, 0.0, 0.0)),
                       (first + 2, (segs[2].length_m, 0.0, 0.0))]
            radii += [segs[0].radius_m, segs[0].radius_m, segs[1].radius_m, segs[2].radius_m,
                      segs[2].radius_m]
        self._parent = np.array(parent, dtype=np.intp)
        self._offset = np.array(offset, dtype=np.float64)
        self._joints = np.array(joints, dtype=np.intp)
        self._point_body = np.array([b for b, _ in points], dtype=np.intp)
        self._point_local = np.array([o for _, o in points], dtype=np.float64)
        self.radii_m: FloatArray = np.array(radii, dtype=np.float64)
        self._frame: FloatArray = np.ascontiguousarray(MODEL_TO_XR.T)
        self._angles: FloatArray = np.zeros(_N_ANGLES)
        self._rot: FloatArray = np.zeros((len(parent), 3, 3))
        self._pos: FloatArray = np.zeros((len(parent), 3))
        self._hinge: FloatArray = np.zeros((3, 3))
        self._tmp: FloatArray = np.zeros((3, 3))
        self._home: tuple[FloatArray, FloatArray] = (np.ascontiguousarray(MODEL_TO_XR),
                                                     np.zeros(3))
        chain_kernel.warm_up()

    def root(self, forearm: XrPose | None) -> tuple[FloatArray, FloatArray]:
        """The forearm frame in OpenXR space: (rotation, origin), for :meth:`compute`."""
        if forearm is None:
            return self._home
        return (np.ascontiguousarray(forearm.matrix() @ MODEL_TO_XR),
                np.array(forearm.position_m, dtype=np.float64))

    def compute(self, pose25_deg: FloatArray, wrist_deg: Sequence[float] | FloatArray = (0.0, 0.0),
                forearm: XrPose | None = None, out: FloatArray | None = None, *,
                root: tuple[FloatArray, FloatArray] | None = None) -> FloatArray:
        """One frame: this hand's 25 curves (its half of :data:`handrig.hand.CURVE_NAMES`,
        in that order, degrees) and (wrist flexion, deviation) in degrees -> the (26, 7)
        poses (:data:`POSE_COLUMNS`), written into ``out`` if given (float64, C order;
        else a new array). ``root``: :meth:`root`'s answer, kept by a caller that sends
        every frame from the same forearm pose (then ``forearm`` is not read)."""
        c = np.asarray(pose25_deg, dtype=np.float64)
        if c.shape != (vocab.CURVES_PER_HAND,):
            raise DataError(f"one hand's pose is {vocab.CURVES_PER_HAND} curves (thumb CMCx .."
                            f" pinky DIPy), got shape {c.shape}")
        w = np.asarray(wrist_deg, dtype=np.float64)
        if w.shape != (2,):
            raise DataError(f"the wrist is 2 angles (flexion, deviation) in degrees, got "
                            f"shape {w.shape}")
        a = self._angles
        a[:2] = w
        a[2:] = c[self._curve_slot]
        np.radians(a, out=a)
        rot, origin = root if root is not None else self.root(forearm)
        if out is None:
            out = np.empty((JOINT_COUNT, 7))
        chain_kernel.chain_poses(a, self._axes, self._parent, self._offset, self._joints,
                                 rot, origin, self._point_body, self._point_local,
                                 self._frame, self._rot, self._pos, self._hinge, self._tmp,
                                 out)
        return out

    def joints(self, pose25_deg: FloatArray, wrist_deg: Sequence[float] | FloatArray = (0.0, 0.0),
               forearm: XrPose | None = None) -> HandJoints:
        """:meth:`compute` as a :class:`HandJoints` record (new arrays)."""
        return HandJoints(self.hand, self.compute(pose25_deg, wrist_deg, forearm),
                          self.radii_m.copy())


@functools.lru_cache(maxsize=8)
def _hand(hand: Hand, hand_length_m: float) -> OpenXrHand:
    return OpenXrHand(hand, hand_length_m)


def hand_joints(pose25_deg: FloatArray, hand: Hand = "ri", *,
                wrist_deg: Sequence[float] | FloatArray = (0.0, 0.0),
                forearm: XrPose | None = None,
                hand_length_m: float = REFERENCE_HAND_LENGTH_M) -> HandJoints:
    """One hand's 26 OpenXR joints from its 25 curves (degrees, vocabulary convention,
    the hand's curves in :data:`handrig.hand.CURVE_NAMES` order), its wrist (flexion,
    deviation) in degrees, and where its forearm is (:class:`XrPose`; None: the wrist at
    the origin, the forearm pointing -Z, the back of the hand up)."""
    return _hand(hand, float(hand_length_m)).joints(pose25_deg, wrist_deg, forearm)


WRIST_SLOTS: dict[Hand, tuple[int, int]] = {
    h: (vocab.ALL_JOINT_NAMES.index(f"{h}WristFlexion"),
        vocab.ALL_JOINT_NAMES.index(f"{h}WristDeviation")) for h in vocab.HANDS}
"""Where each hand's wrist (flexion, deviation) sits in a full 54-value pose."""


def hand_slice(hand: Hand) -> slice:
    """Where ``hand``'s 25 curves sit in the 50 (and in a full 54-value pose)."""
    first = vocab.curve_index(f"{hand}ThumbCMCx")
    return slice(first, first + vocab.CURVES_PER_HAND)


def both_hands(full_pose_deg: FloatArray, *, forearms: dict[Hand, XrPose] | None = None,
               hand_length_m: float = REFERENCE_HAND_LENGTH_M) -> dict[Hand, HandJoints]:
    """Both hands from a full pose (the 50 curves, then the 4 wrist DOFs in
    :data:`handrig.hand.ALL_JOINT_NAMES` order: what an output is handed); ``forearms``:
    each hand's :class:`XrPose` (a hand not named: the default)."""
    p = np.asarray(full_pose_deg, dtype=np.float64)
    if p.shape != (len(vocab.ALL_JOINT_NAMES),):
        raise DataError(f"a full pose is {len(vocab.ALL_JOINT_NAMES)} values (50 curves, 4 "
                        f"wrist DOFs), got shape {p.shape}")
    given = forearms or {}
    return {h: hand_joints(p[hand_slice(h)], h, wrist_deg=p[list(WRIST_SLOTS[h])],
                           forearm=given.get(h), hand_length_m=hand_length_m)
            for h in vocab.HANDS}
