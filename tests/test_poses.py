from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from baseplace.errors import InputError
from baseplace.geometry.poses import (
    BasePose,
    invert_transforms,
    matrix_to_rpy,
    parse_base_pose,
    parse_pose6,
    pose_from_xyz_rpy,
    rpy_to_matrix,
    yaw_of,
)
from baseplace.geometry.surface_poses import plane_base_poses, plane_frame

angles = st.floats(-np.pi, np.pi, allow_nan=False)


@given(angles, st.floats(-1.5, 1.5), angles)
@example(2.0, 1.5, -3.1415926535897927)  # a yaw a rounding above -pi comes back as pi (CI found it)
def test_rpy_matches_scipy_ros_convention(roll, pitch, yaw):
    # ROS: R = Rz(yaw) Ry(pitch) Rx(roll) == scipy extrinsic "xyz" with (roll, pitch, yaw).
    expected = Rotation.from_euler("xyz", [roll, pitch, yaw]).as_matrix()
    np.testing.assert_allclose(rpy_to_matrix(roll, pitch, yaw), expected, atol=1e-12)
    error = np.asarray(matrix_to_rpy(expected)) - [roll, pitch, yaw]
    assert np.all(np.abs(np.angle(np.exp(1j * error))) < 1e-9), error  # -pi and pi are one angle


def test_pose_parsing_and_errors():
    T = parse_pose6("1 2 3 0 0 1.5707963267948966")
    np.testing.assert_allclose(T[:3, 3], [1, 2, 3])
    np.testing.assert_allclose(T[:3, 0], [0, 1, 0], atol=1e-12)  # x axis turned to +y
    with pytest.raises(InputError, match="NaN"):
        parse_pose6("1 2 nan 0 0 0")
    with pytest.raises(InputError, match="6 numbers"):
        parse_pose6("1 2 3")
    with pytest.raises(InputError, match="numbers"):
        parse_base_pose("a b c")
    assert parse_base_pose("1, 2, 0.5") == BasePose(1.0, 2.0, 0.5)


@settings(max_examples=50)
@given(st.lists(st.floats(-5, 5), min_size=6, max_size=6))
def test_invert_transforms_against_numpy_inverse(v):
    T = pose_from_xyz_rpy(v)
    np.testing.assert_allclose(invert_transforms(T), np.linalg.inv(T), atol=1e-9)


def test_base_pose_batch_and_roundtrip():
    poses = np.array([[1.0, -2.0, 0.3], [0.0, 0.5, -2.0]])
    T = BasePose.batch_matrix(poses)
    for row, Ti in zip(poses, T, strict=True):
        np.testing.assert_allclose(Ti, BasePose(*row).matrix(), atol=1e-12)
        back = BasePose.from_matrix(Ti)
        np.testing.assert_allclose([back.x, back.y, back.yaw], row, atol=1e-12)


@pytest.mark.parametrize("shape", [(), (1,), (7,), (3, 5)])
def test_yaw_of_and_from_matrix_agree_with_scipy(shape):
    # Oracle: scipy's intrinsic ZYX Euler angles, whose first angle is the heading of the x axis.
    rng = np.random.default_rng(len(shape) * 10 + sum(shape))
    n = int(np.prod(shape))
    rotations = Rotation.random(n, random_state=rng)
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = rotations.as_matrix()
    T[:, :3, 3] = rng.uniform(-5, 5, (n, 3))
    expected = rotations.as_euler("ZYX")[:, 0]
    yaw = yaw_of(T.reshape(*shape, 4, 4))
    assert yaw.shape == shape
    assert np.all((-np.pi < yaw) & (yaw <= np.pi))
    np.testing.assert_allclose(np.angle(np.exp(1j * (yaw.reshape(n) - expected))), 0.0, atol=1e-9)
    np.testing.assert_array_equal(yaw_of(T[:, :3, :3]).reshape(shape), yaw)  # rotations alike
    rows = BasePose.batch_from_matrix(T)
    for Ti, row, yaw_i in zip(T, rows, yaw.reshape(n), strict=True):
        pose = BasePose.from_matrix(Ti)
        assert (pose.x, pose.y, pose.yaw) == (Ti[0, 3], Ti[1, 3], yaw_i) == tuple(row)
    planar = Rotation.from_euler("z", rows[:, 2:]).as_matrix()  # the floor pose back, again by scipy
    np.testing.assert_allclose(BasePose.batch_matrix(rows)[:, :3, :3], planar, atol=1e-12)


def test_yaw_of_gives_pi_for_a_heading_of_minus_pi():
    T = BasePose(0.0, 0.0, np.pi).matrix()
    T[1, 0] = -0.0  # atan2(-0.0, -1) is -pi: the heading must still come back as pi
    assert float(yaw_of(T)) == np.pi and BasePose.from_matrix(T).yaw == np.pi


def test_plane_poses_on_flat_floor_are_yaw_poses():
    gamma = np.linspace(-3, 3, 7)
    T = plane_base_poses(np.ones(7), 2 * np.ones(7), gamma, [0, 0, 1], 0.0)
    np.testing.assert_allclose(T, BasePose.batch_matrix(np.c_[np.ones(7), 2 * np.ones(7), gamma]), atol=1e-12)


@settings(max_examples=100)
@given(
    st.floats(-0.6, 0.6),
    st.floats(-0.6, 0.6),
    st.floats(-2, 2),
    st.floats(-3, 3),
    st.floats(-3, 3),
    angles,
)
def test_plane_poses_lie_on_the_plane(nx, ny, d, x, y, gamma):
    n = np.array([nx, ny, 1.0])
    n_unit = n / np.linalg.norm(n)
    T = plane_base_poses([x], [y], [gamma], n, d * np.linalg.norm(n))[0]
    R = T[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R[:, 2], n_unit, atol=1e-12)  # base z is the plane normal
    assert n_unit @ T[:3, 3] + d == pytest.approx(0.0, abs=1e-9)  # origin on the plane
    np.testing.assert_allclose(T[:2, 3], [x, y])
    R0 = plane_frame(n)
    # gamma = 0: the base y axis lies in the plane and projects onto +y (seed 000 III-A).
    assert abs(R0[:, 1] @ n_unit) < 1e-12
    assert R0[0, 1] == pytest.approx(0.0, abs=1e-12) and R0[1, 1] > 0
    # gamma rotates about the normal.
    expected = R0 @ Rotation.from_rotvec([0, 0, gamma]).as_matrix()
    np.testing.assert_allclose(R, expected, atol=1e-12)


def test_plane_normal_must_point_up():
    with pytest.raises(InputError, match="point up"):
        plane_frame([0, 0, -1])
    with pytest.raises(InputError, match="non-zero"):
        plane_frame([0, 0, 0])
