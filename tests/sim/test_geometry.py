"""Frames and analytic geometry of the simulator (geometry.md conventions)."""

from __future__ import annotations

import numpy as np
import pytest

from sim_backend.geometry import (
    Rect,
    box_faces,
    camera_rotation,
    laser_normal,
    matrix_rpy,
    rot_z,
    rpy_matrix,
)


def test_nominal_camera_looks_down_with_image_up_along_y() -> None:
    R = camera_rotation(0.0, 0.0, 0.0)
    np.testing.assert_allclose(R @ [0, 0, 1], [0, 0, -1])  # optical axis down
    np.testing.assert_allclose(R @ [1, 0, 0], [1, 0, 0])  # +u is +X
    np.testing.assert_allclose(R @ [0, -1, 0], [0, 1, 0])  # image up (-v) is +Y


def test_rotation_order_is_z_y_x() -> None:
    roll, pitch, yaw = 7.0, -4.0, 12.0
    R = camera_rotation(roll, pitch, yaw)
    nominal = camera_rotation(0.0, 0.0, 0.0)
    np.testing.assert_allclose(R, rot_z(yaw) @ rpy_matrix(roll, pitch, 0.0) @ nominal)
    assert matrix_rpy(rpy_matrix(roll, pitch, yaw)) == pytest.approx((roll, pitch, yaw))


def test_laser_normal_tilts() -> None:
    np.testing.assert_allclose(laser_normal(0.0, 0.0), [0, 0, 1])
    n = laser_normal(0.0, 10.0)  # pitch about Y tips the normal towards +X
    assert n[0] == pytest.approx(np.sin(np.deg2rad(10.0)))
    n = laser_normal(10.0, 0.0)  # roll about X tips it towards -Y
    assert n[1] == pytest.approx(-np.sin(np.deg2rad(10.0)))


def test_rect_plane_segment_is_clipped_exactly() -> None:
    wall = Rect(
        "w",
        np.array([-500.0, 0.0, -1200.0]),
        np.array([0.0, 1.0, 0.0]),
        np.array([0.0, 0.0, 1.0]),
        1000.0,
        800.0,
        np.array([1.0, 0.0, 0.0]),
    )
    a, b = wall.plane_segment(np.array([0.0, 0.0, 1.0]), -800.0)  # the plane Z = -800
    np.testing.assert_allclose(sorted([a[1], b[1]]), [0.0, 1000.0])
    np.testing.assert_allclose([a[2], b[2]], [-800.0, -800.0])
    n = laser_normal(20.0, 0.0)  # tilted along Y: the line leaves through the bottom edge
    a, b = wall.plane_segment(n, -800.0)
    for pt in (a, b):
        assert n @ pt == pytest.approx(-800.0)
        assert -1200.0 - 1e-9 <= pt[2] <= -400.0 + 1e-9 and -1e-9 <= pt[1] <= 1000.0 + 1e-9
    assert wall.plane_segment(np.array([0.0, 0.0, 1.0]), 0.0) is None


def test_box_faces_point_outwards() -> None:
    centre = np.array([100.0, 200.0, -300.0])
    half = np.array([10.0, 20.0, 30.0])
    faces = box_faces("b", centre, rot_z(30.0), half)
    assert len(faces) == 6
    for f in faces:
        mid = f.point(f.size_u / 2, f.size_v / 2)
        assert (mid - centre) @ f.normal > 0
        np.testing.assert_allclose(np.cross(f.axis_u, f.axis_v), f.normal, atol=1e-12)
