"""Forearm orientation from an IMU quaternion: (inclination, rotation) for the sag grid.

Frames and conventions
----------------------
* **Forearm frame**: x distal along the forearm, z dorsal (palm down = z up),
  y = z × x (right-handed; toward the thumb on the right forearm, toward the little
  finger on the left). Same as the MuJoCo hand model (``sim/hand_model.py``).
* **IMU quaternion** ``q``: the orientation of the IMU's body frame in the world
  frame, i.e. ``R_imu.apply(v_imu) = v_world`` (the usual AHRS output). Component
  order is given by ``scalar_first`` (True: w, x, y, z; False: x, y, z, w, scipy's
  default). World frame ``"ENU"`` (z up) or ``"NED"`` (z down).
* **Mount rotation** ``mount``: the forearm frame expressed in the IMU frame,
  ``v_imu = mount.apply(v_forearm)``; identity when the IMU's axes are the forearm
  frame's. So forearm -> world is ``R = R_imu * mount``.
* World up in the forearm frame: ``up = R.inv().apply(up_world)``;
  ``inclination = asin(up.x)`` (-90 hanging down, +90 pointing up; computed as
  ``atan2(up.x, hypot(up.y, up.z))``, which keeps full precision near +-90);
  ``rotation = atan2(up.y, up.z)`` (0 palm down, +90 thumb up, 180 palm up) for the
  right hand, ``atan2(-up.y, up.z)`` for the left (its y axis points ulnar), so the
  rotation is anatomical and the same sag grid serves both hands. Near vertical
  (``hypot(up.y, up.z) < vertical_eps``) the rotation is undefined and set to 0; the
  grid rows at +-90 do not depend on it. Heading (rotation about world up) drops
  out: only the direction of gravity matters.

Bad quaternions: NaN/inf components, or a norm outside
``[min_norm, max_norm]`` (zero included), are **rejected** (``rejected`` counts
them; :meth:`ForearmOrientation.angles` raises :class:`~handrig.errors.DataError`,
:meth:`ForearmOrientation.update` keeps the last good angles and returns
``ok=False``). A finite quaternion whose norm is off 1 by more than ``1e-6`` but
inside the bounds is **repaired** by normalising (``repaired`` counts them).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from handrig.errors import DataError
from handrig.hand import Hand
from handrig.pose import kernels

WorldFrame = Literal["ENU", "NED"]
_UP: dict[str, NDArray[np.float64]] = {"ENU": np.array([0.0, 0.0, 1.0]),
                                        "NED": np.array([0.0, 0.0, -1.0])}
# ENU -> NED basis change (east, north, up) -> (north, east, down); a proper rotation.
_ENU_TO_NED = Rotation.from_matrix([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


class ForearmOrientation:
    """IMU quaternion -> (inclination_deg, rotation_deg) of one forearm.

    ``mount``: a scipy ``Rotation`` or a quaternion in the same component order as the
    IMU's (None = identity). ``scalar_first``: component order of every quaternion this
    object takes or returns. ``world``: "ENU" or "NED". ``hand``: "ri" or "le" (see the
    module docstring for the mirrored rotation). Counters: ``accepted``, ``repaired``,
    ``rejected``; ``last_error`` says why the latest rejection happened.
    """

    def __init__(
        self,
        mount: Rotation | ArrayLike | None = None,
        *,
        scalar_first: bool = False,
        world: WorldFrame = "ENU",
        hand: Hand = "ri",
        vertical_eps: float = 1e-6,
        min_norm: float = 0.5,
        max_norm: float = 1.5,
    ) -> None:
        if world not in _UP:
            raise DataError(f"world frame {world!r}: use 'ENU' (z up) or 'NED' (z down)")
        if hand not in ("ri", "le"):
            raise DataError(f"hand {hand!r}: use 'ri' or 'le'")
        self.scalar_first = scalar_first
        self.world: WorldFrame = world
        self.hand: Hand = hand
        self.vertical_eps = vertical_eps
        self.min_norm = min_norm
        self.max_norm = max_norm
        if mount is None:
            self.mount = Rotation.identity()
        elif isinstance(mount, Rotation):
            self.mount = mount
        else:
            m = np.asarray(mount, dtype=np.float64)
            if m.shape != (4,) or not np.all(np.isfinite(m)) or np.linalg.norm(m) < 1e-9:
                raise DataError(f"mount quaternion {mount!r}: need 4 finite components,"
                                " not all zero")
            self.mount = Rotation.from_quat(m, scalar_first=scalar_first)
        self._up = _UP[world]
        self._mount_m = np.ascontiguousarray(self.mount.as_matrix().T, dtype=np.float64)
        self._up_sign = float(self._up[2])
        self._sign_y = -1.0 if hand == "le" else 1.0
        self.accepted = 0
        self.repaired = 0
        self.rejected = 0
        self.last_error = ""
        self._last: tuple[float, float] | None = None

    def angles(self, quat: ArrayLike) -> tuple[float, float]:
        """(inclination_deg, rotation_deg) for one IMU quaternion; a rejected quaternion
        raises :class:`DataError` (and counts in ``rejected``). The arithmetic is scipy's
        ``(Rotation.from_quat(q) * mount).inv().apply(up)`` written out and compiled
        (:func:`handrig.pose.kernels.forearm_angles`; :meth:`angles_reference` is the
        scipy version, and the tests compare them)."""
        q = quat if isinstance(quat, np.ndarray) and quat.dtype == np.float64 else None
        if q is None or q.shape != (4,):
            try:
                q = np.asarray(quat, dtype=np.float64)
            except (TypeError, ValueError):
                q = np.zeros(0)
            if q.shape != (4,):
                self.rejected += 1
                self.last_error = (f"quaternion must have 4 components, got shape"
                                   f" {np.shape(quat)}")
                raise DataError(self._rejection())
        inc, rot, status = kernels.forearm_angles(
            q, self.scalar_first, self._up_sign, self._mount_m, self._sign_y,
            self.vertical_eps, self.min_norm, self.max_norm)
        if status >= kernels.ANGLES_NONFINITE:
            self.rejected += 1
            v = [float(x) for x in q]
            if status == kernels.ANGLES_NONFINITE:
                self.last_error = f"quaternion {v} has NaN or infinite components"
            else:
                norm = math.sqrt(sum(x * x for x in v))
                self.last_error = (f"quaternion {v} has norm {norm:.3g}, outside"
                                   f" {self.min_norm}..{self.max_norm} (zero or corrupted)")
            raise DataError(self._rejection())
        if status == kernels.ANGLES_REPAIRED:
            self.repaired += 1
        self.accepted += 1
        self._last = (inc, rot)
        return inc, rot

    def _rejection(self) -> str:
        return (f"IMU orientation rejected ({self.rejected} so far): {self.last_error}; "
                f"check the IMU stream and its component order "
                f"(scalar_first={self.scalar_first})")

    def angles_reference(self, quat: ArrayLike) -> tuple[float, float]:
        """:meth:`angles` computed with scipy ``Rotation`` objects (slower; for checks).
        Takes an already valid quaternion; counters are not touched."""
        r = Rotation.from_quat(np.asarray(quat, dtype=np.float64),
                               scalar_first=self.scalar_first) * self.mount
        up = r.inv().apply(self._up)
        y, z = self._sign_y * float(up[1]), float(up[2])
        inc = math.degrees(math.atan2(float(up[0]), math.hypot(y, z)))
        rot = 0.0 if math.hypot(y, z) < self.vertical_eps else math.degrees(math.atan2(y, z))
        return inc, rot

    def update(self, quat: ArrayLike) -> tuple[float, float, bool]:
        """Like :meth:`angles` for the realtime loop: a rejected quaternion does not raise
        but returns the last good angles (or (0, 0) before any) with ``ok=False``."""
        try:
            inc, rot = self.angles(quat)
        except DataError:
            last = self._last if self._last is not None else (0.0, 0.0)
            return last[0], last[1], False
        return inc, rot, True

    def quaternion_for(
        self, inclination_deg: float, rotation_deg: float, heading_deg: float = 0.0
    ) -> NDArray[np.float64]:
        """The IMU quaternion (this object's order, frame, mount and hand) whose
        :meth:`angles` are (``inclination_deg``, ``rotation_deg``): for synthesising IMU
        streams of a forearm path. ``heading_deg``: the forearm's compass heading, which
        does not change the angles."""
        rot = self._sign_y * rotation_deg  # geometric roll about the forearm x axis
        # Forearm -> ENU world: heading about up, then pitch the x axis up, then roll.
        fw = Rotation.from_euler("ZYX", [heading_deg, -inclination_deg, rot], degrees=True)
        if self.world == "NED":
            fw = _ENU_TO_NED * fw
        imu = fw * self.mount.inv()
        return np.asarray(imu.as_quat(scalar_first=self.scalar_first), dtype=np.float64)

    def path(self, inclination_deg: Sequence[float], rotation_deg: Sequence[float],
             heading_deg: float = 0.0) -> NDArray[np.float64]:
        """:meth:`quaternion_for` over a path: (n,) and (n,) -> (n, 4)."""
        return np.array([self.quaternion_for(a, b, heading_deg)
                         for a, b in zip(inclination_deg, rotation_deg, strict=True)])
