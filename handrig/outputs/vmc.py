"""VMC protocol output: the two hands as OSC bundles over UDP to a virtual puppet.

The VMC protocol (sh-akira/VirtualMotionCaptureProtocol, REFERENCE.md section 5)
is OSC over UDP; a receiver (VSeeFace, EVMC4U in Unity, VMC4B in Blender) listens
on port 39539 by default. One bundle per frame holds::

    /VMC/Ext/Root/Pos  (s)"root" (f)px py pz qx qy qz qw     identity
    /VMC/Ext/Bone/Pos  (s)name   (f)px py pz qx qy qz qw     one per bone, local
    /VMC/Ext/OK        (i)1
    /VMC/Ext/T         (f)time_s

Bones: ``RightHand``/``LeftHand`` (the wrist) and the 15 Unity ``HumanBodyBones``
finger bones per hand, ``{Left,Right}{Thumb,Index,Middle,Ring,Little}{Proximal,
Intermediate,Distal}``. Unity's ``ThumbProximal`` is the anatomical thumb CMC, so
the thumb's Proximal/Intermediate/Distal carry CMC/MCP/IP; a finger's carry
MCP/PIP/DIP.

Axis conventions (what a VSeeFace/Unity user should see)
--------------------------------------------------------
Rotations are *local* rotations of a **normalised humanoid** (a VRM avatar, or any
rig whose bones have identity rest rotations in T-pose), so a local rotation is
about the avatar's own axes: Unity X to the avatar's right, Y up, Z the way the
avatar faces. In T-pose with palms down:

* fingers point along +X (right hand) / -X (left hand), palms face -Y, the thumb
  side faces +Z;
* **flexion** (pose value positive) is a rotation about Unity **-Z on the right
  hand and +Z on the left hand** (so the fingertips go down, toward the palm);
* **abduction** (radial positive, toward the thumb) is about Unity **-Y on the
  right hand and +Y on the left** (the tips swing forward, toward +Z);
* finger **twist** (MCPz, pronation-like positive) is about the bone's long axis;
* the thumb points out and forward at 45 deg, pad turned toward the index; its
  flexion carries the tip across the palm, its abduction away from the palm
  (see :mod:`handrig.outputs.skeleton`);
* a 3-DOF joint composes intrinsically flexion, then abduction, then twist
  (R = R_flex R_abd R_twist, the order of the recorder's BVH channels), so
  flexion decodes over the full +-180 deg and abduction within +-90; the wrist
  (``RightHand``) is flexion then deviation, deviation radial positive.

Internally each rotation is built in the right-handed frame that is Unity's with Z
negated, then converted with REFERENCE.md's rule p = (x, y, -z),
q = (-qx, -qy, qz, qw); :func:`decode_bones` inverts it exactly.

The bundle is encoded into a preallocated buffer (every OSC field is 4-byte
aligned, so all floats are written with one numpy assignment) and sent on a
non-blocking UDP socket: fire and forget, a full socket buffer counts an error and
drops the frame. Its bytes equal python-osc's ``OscBundleBuilder`` output (tested).
"""

from __future__ import annotations

import socket
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from handrig import hand
from handrig.clock import Clock, MonotonicClock
from handrig.errors import ConfigError
from handrig.outputs import skeleton
from handrig.outputs.base import Output, OutputStatus, PanelCell
from handrig.outputs.skeleton import Anat

DEFAULT_PORT = 39539
"""The VMC receiver's default UDP port (VSeeFace, EVMC4U)."""

WRIST_NAMES: tuple[str, ...] = (
    "riWristFlexion", "riWristDeviation", "leWristFlexion", "leWristDeviation",
)
"""The 4 wrist DOFs in the order ``wrist_deg`` arrays use everywhere in the outputs."""

_UNITY_SIDE = {"ri": "Right", "le": "Left"}
_UNITY_DIGIT = {"Thumb": "Thumb", "Index": "Index", "Middle": "Middle", "Ring": "Ring",
                "Pinky": "Little"}
_SEGMENTS = ("Proximal", "Intermediate", "Distal")
_NONE = len(hand.CURVE_NAMES) + len(WRIST_NAMES)  # index of the always-zero slot


@dataclass(frozen=True)
class Bone:
    """One VMC bone: its Unity name and which pose values drive it.

    ``abd``/``flex``/``twist`` index the 55-slot value vector (50 curves, 4 wrist DOFs,
    then one always-zero slot).
    """

    name: str
    hand: hand.Hand
    abd: int
    flex: int
    twist: int
    offset_m: tuple[float, float, float]  # local position in the parent, Unity frame


def _rh_vector(v: Anat, side: hand.Hand) -> NDArray[np.float64]:
    """Anatomical components -> Unity-with-Z-negated (right-handed) coordinates."""
    out = np.array([1.0 if side == "ri" else -1.0, 0.0, 0.0])
    up = np.array([0.0, 1.0, 0.0])
    fwd = np.array([0.0, 0.0, -1.0])  # the avatar faces Unity +Z
    return v.out * out + v.up * up + v.fwd * fwd


def _axes(dirs: tuple[Anat, Anat, Anat], side: hand.Hand) -> NDArray[np.float64]:
    """Columns: flexion, abduction, twist rotation axes (right-handed frame)."""
    d, f, b = (_rh_vector(x, side) for x in dirs)
    # a positive rotation about d x f carries d toward f (and d x b toward b)
    return np.column_stack([np.cross(d, f), np.cross(d, b), np.cross(b, f)])


def _build_bones() -> tuple[tuple[Bone, ...], NDArray[np.float64]]:
    bones: list[Bone] = []
    axes: list[NDArray[np.float64]] = []
    n50 = len(hand.CURVE_NAMES)
    for side in hand.HANDS:
        uside = _UNITY_SIDE[side]
        w = 0 if side == "ri" else 2
        hand_off = skeleton.Anat(skeleton.FOREARM_LENGTH_M, 0.0, 0.0)
        bones.append(Bone(f"{uside}Hand", side, n50 + w + 1, n50 + w, _NONE,
                          _unity_point(hand_off, side)))
        axes.append(_axes(skeleton.FINGER_DIRS, side))
        for digit in hand.DIGITS:
            dirs = skeleton.digit_dirs(digit)
            offsets = skeleton.digit_offsets_m(digit)
            if digit == "Thumb":
                names = [("CMCy", "CMCz", "CMCx"), (None, "MCPz", None), (None, "IPz", None)]
            else:
                names = [("MCPx", "MCPy", "MCPz"), (None, "PIPy", None), (None, "DIPy", None)]
            for seg, triple, off in zip(_SEGMENTS, names, offsets[:3], strict=True):
                idx = [hand.curve_index(f"{side}{digit}{n}") if n else _NONE for n in triple]
                bones.append(Bone(f"{uside}{_UNITY_DIGIT[digit]}{seg}", side, idx[0], idx[1],
                                  idx[2], _unity_point(off, side)))
                axes.append(_axes(dirs, side))
    return tuple(bones), np.stack(axes)


def _unity_point(v: Anat, side: hand.Hand) -> tuple[float, float, float]:
    x, y, z = _rh_vector(v, side)
    return (float(x), float(y), float(-z))


BONES, _AXES = _build_bones()
"""The 32 bones sent per frame: per hand (right, left) the hand, then thumb..little."""
BONE_NAMES: tuple[str, ...] = tuple(b.name for b in BONES)

# Conjugating by an improper basis B equals conjugating by the proper -B, with the
# angles negated: B E(s*theta) B^T = R(B e_i, theta) for s = det(B).
_DET = np.sign(np.linalg.det(_AXES))
_BASIS = Rotation.from_matrix(_AXES * _DET[:, None, None])
_BASIS_INV = _BASIS.inv()
_SLOTS = np.array([[b.flex, b.abd, b.twist] for b in BONES], dtype=np.intp)


_BASIS_MATRIX = _BASIS.as_matrix()


def bone_quaternions(values_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """Local Unity quaternions (n_bones, 4) as (qx, qy, qz, qw) for one frame.

    ``values_deg`` is the 55-slot vector: 50 curves, 4 wrist DOFs (:data:`WRIST_NAMES`
    order), and a zero; vocabulary convention. Closed-form numpy (about 10x faster
    than composing scipy Rotations); :func:`bone_quaternions_reference` is the scipy
    version it is tested against.
    """
    half = np.radians(values_deg[_SLOTS] * _DET[:, None]) * 0.5
    c = np.cos(half)
    s = np.sin(half)
    c1, c2, c3 = c[:, 0], c[:, 1], c[:, 2]
    s1, s2, s3 = s[:, 0], s[:, 1], s[:, 2]
    # intrinsic X-Y-Z: q = qx(a1) qy(a2) qz(a3), Hamilton products expanded
    v = np.empty((len(BONES), 3))
    v[:, 0] = s1 * c2 * c3 + c1 * s2 * s3
    v[:, 1] = c1 * s2 * c3 - s1 * c2 * s3
    v[:, 2] = c1 * c2 * s3 + s1 * s2 * c3
    q = np.empty((len(BONES), 4))
    q[:, 3] = c1 * c2 * c3 - s1 * s2 * s3
    # conjugation b q b^-1 keeps w and rotates the vector part by b
    np.einsum("bij,bj->bi", _BASIS_MATRIX, v, out=q[:, :3])
    q[:, 0:2] *= -1.0  # right-handed -> Unity: q = (-qx, -qy, qz, qw)
    return q


def bone_quaternions_reference(values_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`bone_quaternions` by composing scipy Rotations (slow; for tests)."""
    ang = values_deg[_SLOTS] * _DET[:, None]
    rot = _BASIS * Rotation.from_euler("XYZ", ang, degrees=True) * _BASIS_INV
    q = rot.as_quat()
    q[:, 0:2] *= -1.0
    return q


def decode_bones(quats_unity: NDArray[np.float64]) -> NDArray[np.float64]:
    """Invert :func:`bone_quaternions`: (n_bones, 4) Unity quaternions -> 55-slot vector.

    Values on slots no bone drives stay 0; the last (always-zero) slot is 0.
    """
    q = np.array(quats_unity, dtype=np.float64)
    q[:, 0:2] *= -1.0
    e = (_BASIS_INV * Rotation.from_quat(q) * _BASIS).as_euler("XYZ", degrees=True)
    e *= _DET[:, None]
    out = np.zeros(_NONE + 1)
    for k in range(3):
        out[_SLOTS[:, k]] = e[:, k]
    out[_NONE] = 0.0
    return out


def _osc_string(s: str) -> bytes:
    raw = s.encode("ascii") + b"\x00"
    return raw + b"\x00" * (-len(raw) % 4)


_IMMEDIATELY = b"\x00\x00\x00\x00\x00\x00\x00\x01"  # OSC time tag "now"


class _BundleTemplate:
    """A preallocated VMC bundle; float fields are filled by one numpy assignment."""

    def __init__(self, bones: tuple[Bone, ...], scale: float = 1.0) -> None:
        parts: list[bytes] = [b"#bundle\x00", _IMMEDIATELY]
        float_pos: list[int] = []  # byte offsets of the 7 floats of each bone message
        pos = 16

        def add(msg_head: bytes, tail: bytes) -> int:
            nonlocal pos
            body = msg_head + tail
            parts.append(struct.pack(">i", len(body)))
            parts.append(body)
            start = pos + 4 + len(msg_head)
            pos += 4 + len(body)
            return start

        pos_head = _osc_string("/VMC/Ext/Root/Pos") + _osc_string(",sfffffff")
        root_tail = struct.pack(">7f", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
        add(pos_head + _osc_string("root"), root_tail)
        bone_head = _osc_string("/VMC/Ext/Bone/Pos") + _osc_string(",sfffffff")
        for b in bones:
            float_pos.append(add(bone_head + _osc_string(b.name), bytes(28)))
        add(_osc_string("/VMC/Ext/OK") + _osc_string(",i"), struct.pack(">i", 1))
        self.time_pos = add(_osc_string("/VMC/Ext/T") + _osc_string(",f"), bytes(4))
        self.buffer = bytearray(b"".join(parts))
        self._floats = np.frombuffer(self.buffer, dtype=">f4")
        starts = np.array(float_pos, dtype=np.intp) // 4
        self._pos_idx = starts[:, None] + np.arange(3)
        self._rot_idx = starts[:, None] + 3 + np.arange(4)
        self._time_idx = self.time_pos // 4
        self._floats[self._pos_idx] = np.array([b.offset_m for b in bones]) * scale

    def fill(self, quats: NDArray[np.float64], t_s: float) -> bytearray:
        self._floats[self._rot_idx] = quats
        self._floats[self._time_idx] = t_s
        return self.buffer


def parse_host_port(text: str, default_port: int = DEFAULT_PORT, *,
                    key: str = "--vmc") -> tuple[str, int]:
    """``"HOST:PORT"``, ``"HOST"`` or ``":PORT"`` -> (host, port); ConfigError naming
    ``key`` otherwise (the UDP outputs: VMC, the OpenXR hand joints)."""
    host, sep, port_text = text.rpartition(":")
    if not sep:
        host, port_text = text, str(default_port)
    host = host or "127.0.0.1"
    try:
        port = int(port_text)
    except ValueError:
        port = -1
    if not 0 < port < 65536 or not host:
        raise ConfigError("not a UDP destination", key=key, value=text,
                          allowed=f"HOST:PORT with PORT 1..65535, e.g. 127.0.0.1:{default_port}")
    return host, port


class VmcStatus(OutputStatus):
    """VMC's status; on the panel: its target, its rate and its send errors."""

    def cell(self) -> PanelCell:
        return PanelCell("VMC", self.address, rate=True, errors=self.errors)


class VmcSender(Output):
    """Send the two hands to a VMC receiver at most ``rate_hz`` times a second.

    ``send`` is meant to be called every loop tick; it returns at once, without
    sending, until the next send is due on ``clock``. Bone positions (local, metres)
    are the anthropometric hand of :mod:`handrig.outputs.skeleton` scaled to
    ``hand_length_m``; most receivers use only the rotations of finger bones, but one
    set to apply bone positions too moves the avatar's knuckles there, so match the
    avatar's hand length or turn that option off in the receiver. Counters: ``bundles_sent``,
    ``skipped`` (rate limit), ``errors`` (the OS refused the datagram: buffer full,
    no route, receiver port closed), ``last_error`` (its text).
    """

    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT, *,
                 rate_hz: float = 60.0, clock: Clock | None = None,
                 hand_length_m: float = skeleton.HAND_LENGTH_M) -> None:
        if not rate_hz > 0:
            raise ConfigError("VMC send rate must be positive", key="rate_hz", value=rate_hz,
                              allowed="> 0 Hz, e.g. 60")
        self.rate_hz = float(rate_hz)
        self.clock: Clock = clock if clock is not None else MonotonicClock()
        self._period_s = 1.0 / self.rate_hz
        self._next_s = -np.inf
        self._values = np.zeros(_NONE + 1)
        if not 0.05 <= hand_length_m <= 0.5:
            raise ConfigError("implausible hand length", key="hand_length_m",
                              value=hand_length_m, allowed="0.05 .. 0.5 m (adult about 0.19)")
        self._template = _BundleTemplate(BONES, hand_length_m / skeleton.HAND_LENGTH_M)
        try:
            infos = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
        except socket.gaierror as exc:
            raise ConfigError(f"cannot resolve VMC host: {exc}", key="vmc host", value=host,
                              allowed="a host name or IP address") from None
        family, _, _, _, sockaddr = infos[0]
        self.address = (str(sockaddr[0]), int(sockaddr[1]))
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        self._sock.setblocking(False)
        self.bundles_sent = 0
        self.skipped = 0
        self.errors = 0
        self.last_error = ""
        self.bytes_sent = 0

    def encode(self, pose50_deg: NDArray[np.float64], wrist_deg: NDArray[np.float64] | None,
               t_s: float) -> bytearray:
        """The bundle for one frame (a view of the internal buffer; copy to keep it)."""
        v = self._values
        v[:50] = pose50_deg
        if wrist_deg is None:
            v[50:54] = 0.0
        else:
            v[50:54] = wrist_deg
        return self._template.fill(bone_quaternions(v), t_s)

    def send(self, pose50_deg: NDArray[np.float64], wrist_deg: NDArray[np.float64] | None,
             t_s: float) -> bool:
        """Send this frame if one is due; True if a datagram went to the OS.

        ``pose50_deg``: (50,) curves of :data:`handrig.hand.CURVE_NAMES`, degrees,
        vocabulary convention; ``wrist_deg``: (4,) in :data:`WRIST_NAMES` order or None
        (wrists straight); ``t_s``: the pose's time, sent as ``/VMC/Ext/T``.
        """
        now = self.clock.now()
        if now < self._next_s:
            self.skipped += 1
            return False
        self._next_s += self._period_s
        if self._next_s <= now:
            self._next_s = now + self._period_s
        data = self.encode(pose50_deg, wrist_deg, t_s)
        try:
            self._sock.sendto(data, self.address)
        except OSError as exc:  # BlockingIOError (buffer full), ConnectionRefused, ...
            self.errors += 1
            self.last_error = f"VMC send to {self.address[0]}:{self.address[1]} failed: {exc}"
            return False
        self.bundles_sent += 1
        self.bytes_sent += len(data)
        return True

    def stats(self) -> dict[str, object]:
        """Counters for a panel or a JSON summary."""
        return {"vmc": f"{self.address[0]}:{self.address[1]}", "rate_hz": self.rate_hz,
                "bundles_sent": self.bundles_sent, "skipped": self.skipped,
                "errors": self.errors, "last_error": self.last_error}

    def __call__(self, t_s: float, pose_deg: NDArray[np.float64]) -> None:
        """The rig's output hook: ``pose_deg`` = 50 curves then the 4 wrist DOFs
        (:data:`handrig.hand.ALL_JOINT_NAMES` order, which :data:`WRIST_NAMES` follows)."""
        self.send(pose_deg[:50], pose_deg[50:54], t_s)

    def status(self) -> OutputStatus:
        return VmcStatus(
            kind="vmc", name="VMC", address=f"{self.address[0]}:{self.address[1]}",
            frames_written=self.bundles_sent, bytes_written=self.bytes_sent,
            errors=self.errors, last_error=self.last_error)

    def summary(self, duration_s: float) -> tuple[str, dict[str, Any]]:
        """``vmc``: the target, bundles sent, their rate over the run, send errors."""
        st = self.status()
        sent = st.frames_written
        rate_hz = round(sent / duration_s, 1) if duration_s > 0 else None
        said = (f"VMC to {st.address}: {sent} bundles"
                + (f", {rate_hz} Hz" if rate_hz is not None else "")
                + (f", {st.errors} send errors" if st.errors else ""))
        return "vmc", {"target": st.address, "bundles_sent": sent, "rate_hz": rate_hz,
                       "errors": st.errors, "last_error": st.last_error, "said": said}

    def close(self) -> None:
        """Close the socket; further sends count as errors."""
        self._sock.close()

    def __enter__(self) -> VmcSender:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
