"""The one home of frames and pose helpers (docs/frames.md): conventions and round trips.

Rotation helpers take radians; the `*_deg` helpers are the boundary. Tolerances are a few ulps
of double precision times the number of operations (1e-9 and below).
"""

from __future__ import annotations

import numpy as np
import pytest

from drivers.base import pose_matrix, pose_vector
from omnisort_hw.core import frames
from omnisort_hw.core.registration import pose_from_offset

RNG = np.random.default_rng(11)


def random_angles(n: int, limit: float = 1.4) -> np.ndarray:
    return RNG.uniform(-limit, limit, (n, 3))


def test_nominal_camera_looks_down_with_image_up_along_y() -> None:
    R = frames.camera_rotation(0.0, 0.0, 0.0)
    np.testing.assert_allclose(R @ [0, 0, 1], [0, 0, -1])  # optical axis down
    np.testing.assert_allclose(R @ [1, 0, 0], [1, 0, 0])  # +u is +X
    np.testing.assert_allclose(R @ [0, -1, 0], [0, 1, 0])  # image up (-v) is +Y


@pytest.mark.parametrize("angles", random_angles(20))
def test_camera_rotation_is_z_y_x_times_nominal_and_camera_angles_inverts_it(angles) -> None:
    roll, pitch, yaw = angles
    R = frames.camera_rotation(roll, pitch, yaw)
    np.testing.assert_allclose(R, frames.rpy_matrix(roll, pitch, yaw) @ frames.R_NOM, atol=1e-12)
    np.testing.assert_allclose(
        R, frames.rot_z(yaw) @ frames.rot_y(pitch) @ frames.rot_x(roll) @ frames.R_NOM, atol=1e-12
    )
    assert frames.camera_angles(R) == pytest.approx(tuple(angles), abs=1e-9)
    assert frames.rpy_angles(frames.rpy_matrix(*angles)) == pytest.approx(tuple(angles), abs=1e-9)


def test_rpy_deg_is_the_degree_boundary_of_rpy_angles() -> None:
    deg = (7.0, -4.0, 120.0)
    R = frames.rpy_matrix(*np.radians(deg))
    assert frames.rpy_deg(R) == pytest.approx(deg, abs=1e-9)
    # The UR-style pose helper (degrees) and the registration offset agree with it.
    T = frames.pose_from_xyz_rpy(np.array([1.0, 2.0, 3.0]), np.array(deg))
    np.testing.assert_allclose(T[:3, :3], R, atol=1e-12)
    np.testing.assert_allclose(pose_from_offset((1.0, 2.0, 3.0, *deg)), T, atol=1e-12)


def test_right_handed_rotations() -> None:
    q = np.pi / 2
    np.testing.assert_allclose(frames.rot_x(q) @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(frames.rot_y(q) @ [0, 0, 1], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(frames.rot_z(q) @ [1, 0, 0], [0, 1, 0], atol=1e-15)


def test_laser_normal_tilts_and_laser_angles_inverts_it() -> None:
    np.testing.assert_allclose(frames.laser_normal(0.0, 0.0), [0, 0, 1])
    a = np.radians(10.0)
    assert frames.laser_normal(0.0, a)[0] == pytest.approx(np.sin(a))  # pitch tips towards +X
    assert frames.laser_normal(a, 0.0)[1] == pytest.approx(-np.sin(a))  # roll tips towards -Y
    for roll, pitch in RNG.uniform(-0.5, 0.5, (20, 2)):
        n = frames.laser_normal(roll, pitch)
        assert np.linalg.norm(n) == pytest.approx(1.0)
        assert frames.laser_angles(n) == pytest.approx((roll, pitch), abs=1e-12)
        assert frames.laser_angles(-3.0 * n) == pytest.approx((roll, pitch), abs=1e-12)


def test_invert_pose_batched_and_single() -> None:
    T = frames.pose_from_xyz_rotvec(RNG.normal(0, 500, (4, 5, 3)), RNG.normal(0, 60, (4, 5, 3)))
    inv = frames.invert_pose(T)
    assert inv.shape == (4, 5, 4, 4)
    np.testing.assert_allclose(T @ inv, np.broadcast_to(np.eye(4), T.shape), atol=1e-9)
    single = frames.homogeneous(frames.rpy_matrix(0.1, 0.2, 0.3), np.array([10.0, 20.0, 30.0]))
    np.testing.assert_allclose(frames.invert_pose(single), np.linalg.inv(single), atol=1e-12)


def test_rotvec_conversions_are_the_drivers_pose_vectors() -> None:
    xyz, rv = np.array([350.0, -120.0, 300.0]), np.array([0.0, 170.0, 20.0])
    T = frames.pose_from_xyz_rotvec(xyz, rv)
    np.testing.assert_allclose(pose_matrix(xyz, rv), T)
    np.testing.assert_allclose(pose_vector(T), np.concatenate([xyz, rv]), atol=1e-9)
    angle = np.linalg.norm(rv)
    assert frames.rotation_angle_deg(np.eye(3), T[:3, :3]) == pytest.approx(angle, abs=1e-9)


def test_rays_to_plane_and_great_circle_normal() -> None:
    n = frames.laser_normal(0.1, -0.2)
    rays = RNG.normal(size=(50, 3))
    rays[:, 2] = -np.abs(rays[:, 2]) - 0.5
    pts = frames.rays_to_plane(rays, n, -800.0)
    np.testing.assert_allclose(pts @ n, -800.0)
    np.testing.assert_allclose(np.cross(pts, rays), 0.0, atol=1e-9)  # on the rays
    parallel = np.cross(n, [1.0, 0.0, 0.0])
    assert np.all(np.isnan(frames.rays_to_plane(parallel[None], n, -800.0)))
    in_plane = np.cross(n, RNG.normal(size=(30, 3)))
    in_plane /= np.linalg.norm(in_plane, axis=1, keepdims=True)
    got = frames.great_circle_normal(in_plane)
    assert abs(got @ n) == pytest.approx(1.0, abs=1e-12)


def test_nearest_rotation_repairs_a_perturbed_rotation() -> None:
    R = frames.rpy_matrix(0.3, -0.2, 1.0)
    M = R + RNG.normal(0, 1e-4, (3, 3))
    Q = frames.nearest_rotation(M)
    np.testing.assert_allclose(Q @ Q.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(Q) == pytest.approx(1.0)
    assert frames.rotation_angle_deg(Q, R) < 0.02  # within the perturbation's size
