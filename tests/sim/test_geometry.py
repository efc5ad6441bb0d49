"""Analytic geometry of the simulator: rectangles and box faces (frames: tests/core)."""

from __future__ import annotations

import numpy as np
import pytest

from omnisort_hw.core.frames import laser_normal, rot_z
from sim_backend.geometry import Rect, box_faces


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
    n = laser_normal(
        np.radians(20.0), 0.0
    )  # tilted along Y: the line leaves through the bottom edge
    a, b = wall.plane_segment(n, -800.0)
    for pt in (a, b):
        assert n @ pt == pytest.approx(-800.0)
        assert -1200.0 - 1e-9 <= pt[2] <= -400.0 + 1e-9 and -1e-9 <= pt[1] <= 1000.0 + 1e-9
    assert wall.plane_segment(np.array([0.0, 0.0, 1.0]), 0.0) is None


def test_box_faces_point_outwards() -> None:
    centre = np.array([100.0, 200.0, -300.0])
    half = np.array([10.0, 20.0, 30.0])
    faces = box_faces("b", centre, rot_z(np.radians(30.0)), half)
    assert len(faces) == 6
    for f in faces:
        mid = f.point(f.size_u / 2, f.size_v / 2)
        assert (mid - centre) @ f.normal > 0
        np.testing.assert_allclose(np.cross(f.axis_u, f.axis_v), f.normal, atol=1e-12)
