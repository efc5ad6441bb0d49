"""Mapping: laser pixels -> points on the laser plane (S, mm) -> segments around the emitter.

Points on a known plane are projected through the camera and mapped back; the tolerance is
the camera model's own round trip (pixel -> ray -> pixel agrees to ~1e-6 px, i.e. < 1e-3 mm at
the distances used), with margin.
"""

from __future__ import annotations

import numpy as np
import pytest

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.mapping import pixels_to_plane, segments, to_plane_frame

ANGLES = {
    "cam_roll_deg": 3.0,
    "cam_pitch_deg": -4.0,
    "cam_yaw_deg": 7.0,
    "laser_roll_deg": 2.0,
    "laser_pitch_deg": -3.0,
    "laser_distance_mm": 800.0,
}


@pytest.fixture(scope="module")
def calib() -> SystemCalibration:
    return SystemCalibration.from_angles(OcamModel.equidistant(1920, 1920, 185.0), ANGLES, "test")


def on_plane(calib: SystemCalibration, xy: np.ndarray) -> np.ndarray:
    """Points (x, y) of S lifted onto the laser plane n.(p - (0, 0, -d)) = 0."""
    n, d = calib.laser_normal, calib.laser_distance_mm
    z = -d - (xy[:, 0] * n[0] + xy[:, 1] * n[1]) / n[2]
    return np.column_stack([xy, z])


def project(calib: SystemCalibration, pts_S: np.ndarray) -> np.ndarray:
    return calib.model.ray_to_pixel(pts_S @ calib.R_SC)  # S -> C is R_SC^T


def test_pixels_map_back_to_the_points_on_the_plane(calib: SystemCalibration) -> None:
    rng = np.random.default_rng(3)
    xy = rng.uniform(-1500.0, 1500.0, (200, 2))
    pts = on_plane(calib, xy)
    got = pixels_to_plane(project(calib, pts), calib)
    np.testing.assert_allclose(got, pts, atol=0.01)
    # On the plane, and on each pixel's ray.
    n = calib.laser_normal
    np.testing.assert_allclose((got - [0.0, 0.0, -calib.laser_distance_mm]) @ n, 0.0, atol=1e-6)


def test_rays_that_do_not_meet_the_plane_below_give_nan(calib: SystemCalibration) -> None:
    up = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.2]])  # above the horizon of the plane
    px = project(calib, up * 1000.0)
    assert np.all(np.isnan(pixels_to_plane(px, calib)))


def _wall(calib: SystemCalibration, distance: float, bearing_deg: float, n: int) -> np.ndarray:
    """Points of a wall facing the axis at `distance`, `bearing_deg` about Z, 600 mm long."""
    b = np.radians(bearing_deg)
    along = np.linspace(-300.0, 300.0, n)
    xy = np.column_stack(
        [distance * np.cos(b) - along * np.sin(b), distance * np.sin(b) + along * np.cos(b)]
    )
    return on_plane(calib, xy)


def test_segments_are_walls_with_their_distance_and_bearing(calib: SystemCalibration) -> None:
    near, far = _wall(calib, 500.0, 0.0, 120), _wall(calib, 900.0, 90.0, 200)
    speck = on_plane(calib, np.array([[-700.0, -700.0]]))  # a lone red speck
    pts = np.concatenate([far, speck, near, [[np.nan] * 3]])
    segs = segments(pts, calib)
    assert len(segs) == 2  # the speck is dropped, the NaN ignored
    a, b = segs
    assert a.distance_mm == pytest.approx(500.0, abs=0.5)  # sorted by distance
    assert b.distance_mm == pytest.approx(900.0, abs=0.5)
    assert a.bearing_deg == pytest.approx(0.0, abs=0.5)
    assert b.bearing_deg == pytest.approx(90.0, abs=0.5)
    assert len(a.points_S) == 120 and len(b.points_S) == 200
    # Length measured in the plane frame: the wall's 600 mm, stretched by the plane's tilt.
    for seg in segs:
        ends = to_plane_frame(seg.points_S[[0, -1]], calib)
        assert seg.length_mm == pytest.approx(np.linalg.norm(ends[1] - ends[0]), rel=1e-6)
        assert 600.0 <= seg.length_mm <= 600.0 / np.cos(np.radians(5.0))
    summary = a.summary()
    assert summary.points == 120 and summary.distance_mm == pytest.approx(500.0, abs=0.5)


def test_a_gap_splits_a_wall_and_short_runs_are_dropped(calib: SystemCalibration) -> None:
    wall = _wall(calib, 700.0, 180.0, 300)
    gap = np.concatenate([wall[:140], wall[160:]])  # a 40 mm hole (> 25 mm max gap)
    assert len(segments(gap, calib)) == 2
    assert segments(wall[:5], calib) == []  # fewer than min_points
    assert segments(np.full((4, 3), np.nan), calib) == []
