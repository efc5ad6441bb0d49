"""`method1`: the older three-sided (U-shaped) target, solved in closed form.

The side walls' borders give the wall direction Y (their great-circle planes meet along it);
the far wall's border runs along X, so X is perpendicular both to Y and to the far border's
great-circle normal. The borders then place the three walls (known side-wall separation D
sets the scale), and the laser rays cut with the three wall planes give 3D points through
which the laser plane is fitted. No markers, no iteration: the far wall supplies the
constraints the markers supply in the two-sided target.
"""

from __future__ import annotations

import time

import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.system_calibration import (
    SystemCalibration,
    fit_laser_plane,
    place_side_walls,
)
from omnisort_hw.core.features import TargetFeatures
from omnisort_hw.core.frames import great_circle_normal, nearest_rotation, rays_to_plane
from omnisort_hw.core.target_layout import TargetLayout
from omnisort_hw.errors import CalibrationError

WALLS = ("left", "right", "far")


def calibrate_method1(
    features: TargetFeatures,
    model: OcamModel,
    separation_mm: float,
    layout: TargetLayout | None = None,
) -> SystemCalibration:
    """The closed form; `layout`: the target as measured (its separation is then used; the
    closed form has no use for the markers)."""
    t0 = time.perf_counter()
    if layout is not None:
        separation_mm = layout.separation_mm
    missing = [w for w in WALLS if w not in features.walls]
    if missing:
        raise CalibrationError(f"three-sided target: no features for wall(s) {', '.join(missing)}")
    border = {w: model.pixel_to_ray(features.walls[w].border_px) for w in WALLS}
    laser = {w: model.pixel_to_ray(features.walls[w].laser_px) for w in WALLS}
    for w in WALLS:
        if len(border[w]) < 5 or len(laser[w]) < 5:
            raise CalibrationError(f"{w} wall: too few border or laser points for method1")
    m = {w: great_circle_normal(border[w]) for w in WALLS}
    y = np.cross(m["left"], m["right"])
    y /= np.linalg.norm(y)
    # Y points from the boom towards the far wall.
    if y @ border["far"].mean(axis=0) < 0:
        y = -y
    x = np.cross(m["far"], y)
    x /= np.linalg.norm(x)
    if x @ (border["right"].mean(axis=0) - border["left"].mean(axis=0)) < 0:
        x = -x
    R = nearest_rotation(np.stack([x, y, np.cross(x, y)]))
    x_left, z_b = place_side_walls(R, m["left"], m["right"], separation_mm)
    mF = R @ m["far"]  # far border plane normal ~ (0, z_b, -y_far)
    y_far = -mF[2] / mF[1] * z_b
    planes = {
        "left": (np.array([1.0, 0.0, 0.0]), x_left),
        "right": (np.array([1.0, 0.0, 0.0]), x_left + separation_mm),
        "far": (np.array([0.0, 1.0, 0.0]), y_far),
    }
    pts = np.concatenate([rays_to_plane(laser[w] @ R.T, *planes[w]) for w in WALLS])
    n, d, fit_rms = fit_laser_plane(pts)
    calib = SystemCalibration(
        model=model,
        R_SC=R,
        laser_normal=n,
        laser_distance_mm=d,
        method="method1",
        target={
            "kind": features.kind,
            "separation_mm": separation_mm,
            "wall_left_x_mm": float(x_left),
            "far_wall_y_mm": float(y_far),
            "border_z_mm": float(z_b),
        },
        residuals={"laser_plane_rms_mm": fit_rms},
    )
    calib.elapsed_s = time.perf_counter() - t0
    return calib
