"""A cube's position covariance with the calibration's part, and the capture gate."""

from __future__ import annotations

import numpy as np

from omnisort_hw.core.cube_uncertainty import (
    CHI2_2_95,
    UNCERTAIN,
    add_calibration_part,
    capture_radius_mm,
    capture_refusal,
)
from tests.pipeline.sorting_scene import make_cube


def _floor() -> np.ndarray:
    T = np.eye(4)
    T[2, 3] = -1200.0
    return T


def test_yaw_uncertainty_grows_with_the_distance_from_the_camera_foot() -> None:
    sigma_yaw = np.radians(0.5)
    cov = np.diag([0.0, 0.0, sigma_yaw**2])
    near, far = make_cube("red", (0.0, 300.0, -1150.0)), make_cube("red", (0.0, 1000.0, -1150.0))
    from omnisort_hw.core.frames import camera_rotation

    R = camera_rotation(0.0, 0.0, 0.0)
    add_calibration_part([near, far], R, np.zeros(3), _floor(), 100.0, 0.0, cov)
    fit = 0.3**2
    # A yaw turns a point about the camera's vertical: it moves by its horizontal distance.
    for cube, dist in ((near, 300.0), (far, 1000.0)):
        assert cube.position_cov_xy is not None
        total = np.trace(cube.position_cov_xy) - 2 * fit
        assert np.isclose(np.sqrt(total), dist * sigma_yaw, rtol=0.02)


def test_capture_gate_uses_the_95_percent_radius() -> None:
    cube = make_cube("red", (0.0, 500.0, -1150.0))
    cube.position_cov_xy = np.diag([4.0**2, 1.0**2])
    assert np.isclose(capture_radius_mm(cube), 4.0 * np.sqrt(CHI2_2_95))
    assert capture_refusal(cube, 10.0) is None
    reason = capture_refusal(cube, 9.0)
    assert reason is not None and reason.startswith(UNCERTAIN)
