"""The cell's pictures: a cube's outline stays visible on every cube colour (white on black:
the yellow outline vanished on a yellow cube), the legend carries the verdict, and the
registration's base axes land where the calibration projects them."""

from __future__ import annotations

import numpy as np
import pytest

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.cell_pictures import draw_cubes, draw_registration
from omnisort_hw.core.cube_location import Cube
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.overlays import project_S

SIZE = 640
ZERO = dict.fromkeys(
    ("cam_roll_deg", "cam_pitch_deg", "cam_yaw_deg", "laser_roll_deg", "laser_pitch_deg"), 0.0
)


def _calib() -> SystemCalibration:
    model = OcamModel.equidistant(SIZE, SIZE, 185.0)
    return SystemCalibration.from_angles(model, {**ZERO, "laser_distance_mm": 950.0}, "t")


def _cube(outline: np.ndarray, colour: str) -> Cube:
    return Cube(
        color=colour,
        center_S=np.array([0.0, 0.0, -1000.0]),
        center_B=np.array([0.0, 0.0, 50.0]),
        yaw_S_deg=0.0,
        yaw_B_deg=0.0,
        sigma_xy_mm=(0.5, 0.3),
        sigma_yaw_deg=0.1,
        rms_px=0.2,
        area_px=400,
        outline_points=len(outline),
        laser_points=0,
        bbox=(300, 300, 40, 40),
        outline_px=outline,
    )


@pytest.mark.parametrize("bgr", [(0, 255, 255), (0, 0, 255), (255, 255, 255), (0, 0, 0)])
def test_a_cube_outline_is_visible_on_every_cube_colour(bgr: tuple[int, int, int]) -> None:
    image = np.zeros((SIZE, SIZE, 3), np.uint8)
    image[300:340, 300:340] = bgr
    side = np.arange(300, 340, dtype=float)
    outline = np.concatenate(
        [
            np.column_stack([side, np.full_like(side, 300.0)]),
            np.column_stack([np.full_like(side, 300.0), side]),
        ]
    )
    T_SB = np.eye(4)
    T_SB[:3, 3] = [0.0, 0.0, -1050.0]
    pic = draw_cubes(image, _calib(), T_SB, [_cube(outline, "yellow")], ["PASS: locate"])
    assert pic.shape[0] == SIZE and pic.shape[1] > SIZE  # the legend beside the image
    on = pic[outline[:, 1].astype(int), outline[:, 0].astype(int)].astype(int)
    # The outline's own pixels are white and a black ring holds them off any cube colour.
    assert np.all(on.min(axis=1) >= 250), on[:5]
    ring = pic[302, 302:310].astype(int)  # inside the cube, next to the outline
    assert ring.max(axis=1).min() <= 5 or bgr == (0, 0, 0), ring


def test_the_base_axes_start_where_the_calibration_projects_the_base() -> None:
    calib = _calib()
    T_SB = np.eye(4)
    T_SB[:3, 3] = [150.0, -100.0, -1200.0]  # the base on the floor, below the camera
    image = np.full((SIZE, SIZE, 3), 90, np.uint8)
    corners = np.array([[100.0, 100.0], [120.0, 100.0]])
    pic = draw_registration(image, calib, corners, T_SB, ["PASS: robot registration"])
    u, v = np.round(project_S(calib, T_SB[:3, 3][None])[0]).astype(int)
    assert not np.array_equal(pic[v, u], image[v, u])  # an axis is drawn there
    assert np.array_equal(pic[50, 50], image[50, 50])  # and not everywhere
    assert tuple(pic[100, 100]) == (0, 0, 255)  # the first corner, red
