"""How the IMU sits on the forearm, found from two held poses (``[imu] mount_xyzw``).

The mount is the forearm frame expressed in the IMU frame (``v_imu = mount.apply(
v_forearm)``, :mod:`handrig.pose.orientation`): forearm x distal, z dorsal, y toward the
thumb (right hand). Two poses fix it from gravity alone:

1. forearm level, palm down: world up is the forearm's +z;
2. forearm level, palm vertical, thumb up: world up is the forearm's +y.

In each pose the IMU's quaternion (IMU body to world, ENU) gives world up in IMU
coordinates, ``u = R_imu.inv().apply(up)``; the mount maps forearm +z to ``u_level``
and +y to ``u_vertical`` (scipy's ``align_vectors``, the first pair weighted most).
Heading never enters: the forearm may point anywhere in each pose. The two
measured directions must be about a quarter turn apart, else the poses were not
held as asked.

:func:`askew_mount` is the other way round, for emulating an IMU fixed askew on
the forearm (``handrig sim-glove --imu-askew``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from handrig.errors import DataError

FloatArray = NDArray[np.float64]

IMU_STEPS: tuple[tuple[str, str], ...] = (
    ("forearm-level", "Forearm level, palm down, hand open: rest the elbow on a table and "
                      "hold the forearm horizontal."),
    ("palm-vertical", "Forearm still level, turn the palm to vertical, thumb up, hand open."),
)
"""The two poses ``handrig calibrate glove`` adds when the glove sends an orientation."""
UP = np.array([0.0, 0.0, 1.0])
HOLD_SPREAD_DEG = 10.0
MIN_ANGLE_DEG, MAX_ANGLE_DEG = 60.0, 120.0
"""How far apart (degrees) the two measured up directions may be: a quarter turn, give
or take a sloppy hold."""


def up_in_imu(quats_xyzw: FloatArray) -> FloatArray:
    """World up in IMU coordinates over the held samples (m, 4), x y z w: the
    component-wise median, normalised, so the tail of the move into the pose or the
    start of the next one does not pull it; at least half the samples must lie within
    :data:`HOLD_SPREAD_DEG` of it."""
    q = np.asarray(quats_xyzw, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 4 or len(q) == 0:
        raise DataError(f"no IMU orientation to measure from (quaternions of shape {q.shape})")
    ups = Rotation.from_quat(q).inv().apply(UP)
    mid = np.median(ups, axis=0)
    norm = float(np.linalg.norm(mid))
    if norm < 1e-6:
        raise DataError("the IMU's up direction could not be measured; hold still and retry")
    mid /= norm
    near = np.degrees(np.arccos(np.clip(ups @ mid, -1.0, 1.0))) <= HOLD_SPREAD_DEG
    if near.mean() < 0.5:
        raise DataError(f"the forearm moved during the hold (only {near.mean():.0%} of the "
                        f"samples within {HOLD_SPREAD_DEG:g} deg of the median); hold it "
                        "still and run the calibration again")
    return mid


def mount_from_poses(up_level: FloatArray, up_vertical: FloatArray) -> Rotation:
    """The mount rotation from world up seen by the IMU in the two poses (module docstring)."""
    angle = math.degrees(math.acos(float(np.clip(np.dot(up_level, up_vertical), -1.0, 1.0))))
    if not MIN_ANGLE_DEG <= angle <= MAX_ANGLE_DEG:
        raise DataError(
            f"the two forearm poses are {angle:.0f} deg apart, not about 90: hold the forearm "
            "level palm down, then level with the palm vertical and the thumb up")
    rot, _ = Rotation.align_vectors(np.array([up_level, up_vertical]),
                                    np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]),
                                    weights=np.array([10.0, 1.0]))
    return rot


def mount_xyzw(mount: Rotation) -> tuple[float, float, float, float]:
    """The mount as glove.toml's ``mount_xyzw`` (rounded to 1e-6, w >= 0)."""
    q = mount.as_quat()
    if q[3] < 0:
        q = -q
    x, y, z, w = (round(float(v), 6) for v in q)
    return (x, y, z, w)


def askew_mount(yaw_deg: float, roll_deg: float) -> Rotation:
    """The mount of an IMU turned ``yaw_deg`` about the forearm's dorsal axis (z), then
    ``roll_deg`` about its own long axis (x), from the aligned position: its body axes
    in forearm coordinates are ``S = Rz(yaw) Rx(roll)``, so ``mount = S.inv()``."""
    return Rotation.from_euler("ZX", [yaw_deg, roll_deg], degrees=True).inv()


def imu_quaternion(forearm: Rotation, mount: Rotation) -> FloatArray:
    """What an IMU with ``mount`` reports when the forearm's orientation is ``forearm``
    (``R_imu = R_forearm * mount.inv()``), x y z w."""
    return np.asarray((forearm * mount.inv()).as_quat(), dtype=np.float64)


def angle_between_deg(a: Rotation, b: Rotation) -> float:
    """The angle of the rotation that takes ``a`` to ``b``, degrees."""
    return float(np.degrees((a.inv() * b).magnitude()))
