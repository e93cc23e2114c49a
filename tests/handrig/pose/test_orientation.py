"""ForearmOrientation: IMU quaternion + mount -> (inclination, rotation), and back."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from handrig.errors import DataError
from handrig.pose.orientation import ForearmOrientation

ANGLE = st.floats(-89.0, 89.0)
ROT = st.floats(-179.0, 179.0)


def _forearm_to_enu(x_world: list[float], z_world: list[float]) -> Rotation:
    """The rotation taking the forearm axes (x distal, z dorsal) onto these world vectors."""
    x, z = np.array(x_world, float), np.array(z_world, float)
    y = np.cross(z, x)
    return Rotation.from_matrix(np.column_stack([x, y, z]))


@pytest.mark.parametrize(("x_world", "z_world", "expect"), [
    ([1, 0, 0], [0, 0, 1], (0.0, 0.0)),  # horizontal, palm down
    ([0, 1, 0], [0, 0, -1], (0.0, 180.0)),  # horizontal, palm up (heading north)
    ([1, 0, 0], [0, -1, 0], (0.0, 90.0)),  # forearm y (radial) up: thumb up, right hand
    ([0, 0, -1], [1, 0, 0], (-90.0, 0.0)),  # hanging straight down
    ([0, 0, 1], [0, 1, 0], (90.0, 0.0)),  # pointing up
    ([math.cos(0.5), 0, math.sin(0.5)], [-math.sin(0.5), 0, math.cos(0.5)],
     (math.degrees(0.5), 0.0)),
])
def test_named_poses_right_hand_enu(x_world: list[float], z_world: list[float],
                                    expect: tuple[float, float]) -> None:
    fo = ForearmOrientation()
    q = _forearm_to_enu(x_world, z_world).as_quat()
    inc, rot = fo.angles(q)
    assert inc == pytest.approx(expect[0], abs=1e-9)
    assert (rot - expect[1] + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-9)


def test_left_hand_rotation_is_anatomical() -> None:
    # Left forearm, thumb up: its thumb side is -y of the right-handed forearm frame,
    # so world up is -y; anatomically that is +90 for the left hand, -90 for the right.
    q = _forearm_to_enu([1, 0, 0], [0, 1, 0]).as_quat()
    assert ForearmOrientation(hand="le").angles(q)[1] == pytest.approx(90.0)
    assert ForearmOrientation(hand="ri").angles(q)[1] == pytest.approx(-90.0)


@settings(max_examples=60, deadline=None)
@given(inc=ANGLE, rot=ROT, heading=st.floats(-180, 180), scalar_first=st.booleans(),
       world=st.sampled_from(["ENU", "NED"]), hand=st.sampled_from(["ri", "le"]),
       seed=st.integers(0, 1000))
def test_quaternion_for_round_trips(inc: float, rot: float, heading: float,
                                    scalar_first: bool, world: str, hand: str,
                                    seed: int) -> None:
    mount = Rotation.random(random_state=seed)
    fo = ForearmOrientation(mount, scalar_first=scalar_first, world=world,  # type: ignore[arg-type]
                            hand=hand)  # type: ignore[arg-type]
    q = fo.quaternion_for(inc, rot, heading)
    a, b = fo.angles(q)
    assert a == pytest.approx(inc, abs=1e-7)
    assert b == pytest.approx(rot, abs=1e-7)
    assert fo.angles_reference(q) == pytest.approx((a, b), abs=1e-9)


def test_heading_and_world_frame_drop_out() -> None:
    enu, ned = ForearmOrientation(world="ENU"), ForearmOrientation(world="NED")
    q = enu.quaternion_for(30.0, -60.0, 0.0)
    for heading in (45.0, 170.0):
        turned = (Rotation.from_euler("z", heading, degrees=True)
                  * Rotation.from_quat(q)).as_quat()
        assert enu.angles(turned) == pytest.approx((30.0, -60.0))
    # the same physical orientation written in NED coordinates
    c = Rotation.from_matrix([[0, 1, 0], [1, 0, 0], [0, 0, -1]])
    assert ned.angles((c * Rotation.from_quat(q)).as_quat()) == pytest.approx((30.0, -60.0))


def test_scalar_order_matters_and_is_honoured() -> None:
    last, first = ForearmOrientation(), ForearmOrientation(scalar_first=True)
    q_last = last.quaternion_for(-20.0, 45.0)
    q_first = np.roll(q_last, 1)
    assert first.angles(q_first) == pytest.approx(last.angles(q_last))


def test_mount_rotation_is_applied() -> None:
    # IMU strapped with its x axis along the forearm's -z (pointing palmar)...
    mount = _forearm_to_enu([0, 0, 1], [-1, 0, 0]).inv()
    fo = ForearmOrientation(mount)
    forearm = _forearm_to_enu([1, 0, 0], [0, 0, 1])  # palm down, horizontal
    imu = forearm * mount.inv()
    assert fo.angles(imu.as_quat()) == pytest.approx((0.0, 0.0), abs=1e-9)
    assert ForearmOrientation().angles(imu.as_quat()) != pytest.approx((0.0, 0.0), abs=1)


def test_vertical_singularity_gives_rotation_zero() -> None:
    fo = ForearmOrientation()
    for rot in (-120.0, 0.0, 75.0):
        assert fo.angles(fo.quaternion_for(90.0, rot)) == pytest.approx((90.0, 0.0))
        assert fo.angles(fo.quaternion_for(-90.0, rot)) == pytest.approx((-90.0, 0.0))


def test_bad_quaternions_are_rejected_or_repaired_and_counted() -> None:
    fo = ForearmOrientation()
    good = fo.quaternion_for(10.0, 20.0)
    for bad in ([0, 0, 0, 0], [math.nan, 0, 0, 1], [0, math.inf, 0, 1], [0, 0, 0, 3.0]):
        with pytest.raises(DataError, match="rejected"):
            fo.angles(bad)
    assert fo.rejected == 4 and fo.repaired == 0
    assert fo.angles(1.2 * good) == pytest.approx((10.0, 20.0))
    assert fo.repaired == 1
    assert fo.update([0, 0, 0, 0]) == pytest.approx((10.0, 20.0, False))
    assert fo.rejected == 5 and "norm" in fo.last_error
    assert fo.update(good) == pytest.approx((10.0, 20.0, True))
    assert fo.accepted == 2
    with pytest.raises(DataError, match="4 components"):
        fo.angles([0, 0, 1])
    with pytest.raises(DataError, match="world frame"):
        ForearmOrientation(world="NWU")  # type: ignore[arg-type]
