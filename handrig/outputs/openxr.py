"""OpenXR hand joints over UDP: the operator's two hands as 26 joints each, a fixed layout.

For peers that take a tracked human hand (an OpenXR application, Isaac Teleop's hand
trackers) rather than a robot's joints. Each frame the loop writes, both hands go out as
:func:`handrig.pose.openxr_hand.hand_joints` computes them (XR_EXT_hand_tracking's joint
order, names and axes; metres), one UDP datagram per hand, at most ``rate_hz`` frames a
second. The layout (docs/openxr.md), little-endian, 856 bytes::

    offset  type        field
     0      4 bytes     magic b"HRXR"
     4      uint16      version (1)
     6      uint8       hand: 0 right, 1 left
     7      uint8       joint count (26)
     8      uint32      frame number (both hands of a frame share it)
    12      uint32      0 (reserved)
    16      float64     time of the pose, seconds since the run started
    24      26 x 8 float32   per joint, in XrHandJointEXT order:
                        px py pz (metres), qx qy qz qw, radius (metres)

Why this transport: a fixed binary layout is one ``struct``/``numpy.frombuffer`` call (or
a packed C struct) in any language, needs no OSC or JSON library, and mirrors
``XrHandJointLocationEXT`` (pose and radius) field for field; one hand per datagram
keeps each under a 1500-byte Ethernet frame (no IP fragmentation on a LAN) and lets a
peer take one hand only. UDP, fire and forget like the VMC output: a late hand pose
is worth nothing, so a full socket buffer drops the frame and counts an error.

Where the hands are: the glove measures no position, so each forearm has a fixed
:class:`~handrig.pose.openxr_hand.XrPose` (default: the wrists 0.2 m apart at the
origin's height, forearms pointing -Z, palms down); the wrist angles and fingers are
the pose's.
"""

from __future__ import annotations

import socket
import struct
from typing import Any

import numpy as np
from numpy.typing import NDArray

from handrig import hand as vocab
from handrig.clock import Clock, MonotonicClock
from handrig.errors import ConfigError
from handrig.hand import Hand
from handrig.outputs.base import Output, OutputStatus, PanelCell
from handrig.outputs.vmc import parse_host_port
from handrig.pose.hand_geometry import REFERENCE_HAND_LENGTH_M
from handrig.pose.openxr_hand import (
    JOINT_COUNT,
    WRIST_SLOTS,
    OpenXrHand,
    XrPose,
    hand_slice,
)

DEFAULT_PORT = 39540
"""The default UDP port (VMC's 39539 plus one; OpenXR names none)."""
DEFAULT_RATE_HZ = 90.0
"""Frames a second by default: a common headset display rate."""
MAGIC = b"HRXR"
VERSION = 1
HEADER = struct.Struct("<4sHBBIId")
"""magic, version, hand (0 right, 1 left), joint count, frame number, reserved, time."""
FLOATS_PER_JOINT = 8  # px py pz qx qy qz qw radius
DATAGRAM_BYTES = HEADER.size + JOINT_COUNT * FLOATS_PER_JOINT * 4
HAND_CODE: dict[Hand, int] = {"ri": 0, "le": 1}
DEFAULT_FOREARMS: dict[Hand, XrPose] = {
    "ri": XrPose((0.1, 0.0, 0.0)),
    "le": XrPose((-0.1, 0.0, 0.0)),
}
"""Where each wrist sits when nobody says: 0.2 m apart, forearms pointing -Z, palms down."""


def decode(datagram: bytes) -> tuple[Hand, int, float, NDArray[np.float32]]:
    """One datagram -> (hand, frame number, time in s, (26, 8) joints): the reader's side
    of the layout (tests, and a Python peer). ConfigError if it is not one of ours."""
    if len(datagram) != DATAGRAM_BYTES:
        raise ConfigError("not an OpenXR hand datagram", value=f"{len(datagram)} bytes",
                          allowed=f"{DATAGRAM_BYTES} bytes")
    magic, version, code, count, frame, _, t_s = HEADER.unpack_from(datagram)
    if magic != MAGIC or version != VERSION or count != JOINT_COUNT or code not in (0, 1):
        raise ConfigError("not an OpenXR hand datagram", value=repr(datagram[:8]),
                          allowed=f"magic {MAGIC!r}, version {VERSION}, {JOINT_COUNT} joints")
    joints = np.frombuffer(datagram, dtype="<f4", offset=HEADER.size).reshape(
        JOINT_COUNT, FLOATS_PER_JOINT)
    return ("ri" if code == 0 else "le"), int(frame), float(t_s), joints


class OpenXrStatus(OutputStatus):
    """The OpenXR sender's status; on the panel: "XR", its target and send errors."""

    def cell(self) -> PanelCell:
        return PanelCell("XR", self.address, errors=self.errors)


class OpenXrSender(Output):
    """Send both hands' OpenXR joints to ``host:port``, at most ``rate_hz`` frames a second.

    ``forearms``: each hand's forearm pose (:data:`DEFAULT_FOREARMS` for a hand not
    named); ``hands``: which hands to send. Counters as the VMC sender's:
    ``frames_sent``, ``skipped`` (rate limit), ``errors`` (the OS refused a datagram),
    ``last_error``.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT, *,
                 rate_hz: float = DEFAULT_RATE_HZ, clock: Clock | None = None,
                 hand_length_m: float = REFERENCE_HAND_LENGTH_M,
                 forearms: dict[Hand, XrPose] | None = None,
                 hands: tuple[Hand, ...] = vocab.HANDS) -> None:
        if not rate_hz > 0:
            raise ConfigError("OpenXR send rate must be positive", key="rate_hz",
                              value=rate_hz, allowed="> 0 Hz, e.g. 90")
        if not hands or any(h not in vocab.HANDS for h in hands):
            raise ConfigError("unknown hands", key="hands", value=hands,
                              allowed="'ri', 'le' or both")
        self.rate_hz = float(rate_hz)
        self.clock: Clock = clock if clock is not None else MonotonicClock()
        self._period_s = 1.0 / self.rate_hz
        self._next_s = -np.inf
        poses = {**DEFAULT_FOREARMS, **(forearms or {})}
        self._hands = []
        for h in hands:
            fk = OpenXrHand(h, hand_length_m)
            self._hands.append((h, fk, fk.root(poses[h]), hand_slice(h),
                                np.array(WRIST_SLOTS[h], dtype=np.intp)))
        self._buffers = []
        for h, fk, *_ in self._hands:
            buf = bytearray(DATAGRAM_BYTES)
            HEADER.pack_into(buf, 0, MAGIC, VERSION, HAND_CODE[h], JOINT_COUNT, 0, 0, 0.0)
            floats = np.frombuffer(buf, dtype="<f4", offset=HEADER.size).reshape(
                JOINT_COUNT, FLOATS_PER_JOINT)
            floats[:, 7] = fk.radii_m
            self._buffers.append((buf, floats))
        self._poses = np.empty((JOINT_COUNT, 7))
        try:
            infos = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
        except socket.gaierror as exc:
            raise ConfigError(f"cannot resolve the OpenXR host: {exc}", key="--openxr",
                              value=host, allowed="a host name or IP address") from None
        family, _, _, _, sockaddr = infos[0]
        self.address = (str(sockaddr[0]), int(sockaddr[1]))
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        self._sock.setblocking(False)
        self.frames_sent = 0
        self.skipped = 0
        self.errors = 0
        self.last_error = ""
        self.bytes_sent = 0

    def encode(self, t_s: float, pose_deg: NDArray[np.float64]) -> list[bytearray]:
        """The datagrams of one frame (views of internal buffers; copy to keep them).
        ``pose_deg``: the full pose, 50 curves then the 4 wrist DOFs, degrees."""
        out = []
        for (_, fk, root, curves, wrist), (buf, floats) in zip(
                self._hands, self._buffers, strict=True):
            fk.compute(pose_deg[curves], pose_deg[wrist], out=self._poses, root=root)
            floats[:, :7] = self._poses
            struct.pack_into("<I", buf, 8, self.frames_sent & 0xFFFFFFFF)
            struct.pack_into("<d", buf, 16, t_s)
            out.append(buf)
        return out

    def __call__(self, t_s: float, pose_deg: NDArray[np.float64]) -> None:
        """The rig's output hook: sends this frame if one is due (never blocks)."""
        now = self.clock.now()
        if now < self._next_s:
            self.skipped += 1
            return
        self._next_s += self._period_s
        if self._next_s <= now:
            self._next_s = now + self._period_s
        sent = False
        for data in self.encode(t_s, pose_deg):
            try:
                self._sock.sendto(data, self.address)
            except OSError as exc:  # BlockingIOError (buffer full), ConnectionRefused, ...
                self.errors += 1
                self.last_error = (f"OpenXR send to {self.address[0]}:{self.address[1]} "
                                   f"failed: {exc}")
                continue
            self.bytes_sent += len(data)
            sent = True
        if sent:
            self.frames_sent += 1

    def status(self) -> OutputStatus:
        return OpenXrStatus(
            kind="openxr", name="OpenXR hands", address=f"{self.address[0]}:{self.address[1]}",
            frames_written=self.frames_sent, bytes_written=self.bytes_sent,
            errors=self.errors, last_error=self.last_error)

    def summary(self, duration_s: float) -> tuple[str, dict[str, Any]]:
        """``openxr``: the target, frames sent (a datagram per hand each), their rate over
        the run, send errors."""
        st = self.status()
        sent = st.frames_written
        rate_hz = round(sent / duration_s, 1) if duration_s > 0 else None
        said = (f"OpenXR hand joints to {st.address}: {sent} frames"
                + (f", {rate_hz} Hz" if rate_hz is not None else "")
                + (f", {st.errors} send errors" if st.errors else ""))
        return "openxr", {"target": st.address, "frames_sent": sent,
                          "hands": [h for h, *_ in self._hands], "rate_hz": rate_hz,
                          "errors": st.errors, "last_error": st.last_error, "said": said}

    def close(self) -> None:
        """Close the socket; further sends count as errors."""
        self._sock.close()

    def __enter__(self) -> OpenXrSender:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def parse_target(text: str) -> tuple[str, int]:
    """``--openxr``'s ``HOST:PORT`` (or ``HOST``, ``:PORT``) -> (host, port)."""
    return parse_host_port(text, DEFAULT_PORT, key="--openxr")
