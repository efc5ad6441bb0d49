"""`joint` on the three-sided target: the robust weighted refinement of `joint` on the three
walls' borders and laser lines, started from method1's closed form.

The far wall supplies what the markers supply on the two-sided target, so markers are not
needed (both marker layouts work), and the borders are taken at one height, or, with a target
description, at each wall's measured height. (Adding the markers the image shows at their
described positions was tried on the authors' three-sided render and made the laser pitch
worse, 0.13 against 0.09 degree: its far-wall corner markers sit a pixel off their described
centres, and its far border is tilted 0.09 degree by the texture filtering, which markers do
not undo; see docs/calibration.md.)
"""

from __future__ import annotations

import time

import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.covariance import fit_covariance
from omnisort_hw.core.extrinsics.joint_weighted import (
    LineStore,
    _outcome,
    _refine,
    _WeightedProblem,
)
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration, pixel_scale
from omnisort_hw.core.features import TargetFeatures
from omnisort_hw.core.frames import camera_angles, camera_rotation, laser_angles, laser_normal
from omnisort_hw.core.target_layout import TargetLayout

WALLS3 = ("left", "right", "far")


class ThreeSidedProblem(_WeightedProblem):
    """`joint` on the three-sided target: residuals (pixels) of the three borders and the
    three laser lines for (camera roll/pitch/yaw, laser roll/pitch/distance, left wall X,
    border height, far wall Y). The far wall (along X at Y = y_far) supplies what the markers
    supply on the two-sided target, so markers are not needed (both marker layouts work)."""

    def __init__(
        self,
        border: dict[str, np.ndarray],
        laser: dict[str, np.ndarray],
        model: OcamModel,
        separation: float,
        border_steps: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        self.border_steps = np.asarray(border_steps, float)
        self.border = dict(border)
        self.laser = dict(laser)
        self.scale_border = {w: pixel_scale(model, r) for w, r in border.items()}
        self.scale_laser = {w: pixel_scale(model, r) for w, r in laser.items()}
        self.separation = separation
        self.weights = {"border": 1.0, "laser": 1.0}
        self.inflation: dict[str, float] = {}

    def normals_S(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Great-circle normals in S of the borders and laser lines, rows in WALLS3 order."""
        n = laser_normal(p[3], p[4])
        d, x_left, z_b, y_far = p[5], p[6], p[7], p[8]
        xs = np.array([x_left, x_left + self.separation])
        zb = z_b + self.border_steps  # each wall's border height above the left one's
        border = np.array([[-zb[0], 0.0, xs[0]], [-zb[1], 0.0, xs[1]], [0.0, zb[2], -y_far]])
        # Side walls X = x: the laser line runs along u = (0, -n_z, n_y) through (x, 0, z).
        z_side = -d - n[0] * xs / n[2]
        side = np.cross(np.stack([xs, np.zeros(2), z_side], axis=1), np.array([0.0, -n[2], n[1]]))
        # Far wall Y = y_far: along u = (-n_z, 0, n_x) through (0, y_far, z).
        far = np.cross(
            np.array([0.0, y_far, -d - n[1] * y_far / n[2]]), np.array([-n[2], 0.0, n[0]])
        )
        laser = np.vstack([side, far])
        border /= np.linalg.norm(border, axis=1, keepdims=True)
        laser /= np.linalg.norm(laser, axis=1, keepdims=True)
        return border, laser

    def residual_blocks(self, p: np.ndarray) -> dict[str, np.ndarray]:
        """Signed distances (px) of every border and laser point from its model line."""
        R = camera_rotation(p[0], p[1], p[2])
        border, laser = (m @ R for m in self.normals_S(p))
        out = {}
        for i, w in enumerate(WALLS3):
            out[f"border_{w}"] = (self.border[w] @ border[i]) * self.scale_border[w]
            out[f"laser_{w}"] = (self.laser[w] @ laser[i]) * self.scale_laser[w]
        return out

    def line_store(self) -> LineStore:
        """Border and laser rays and scales of each wall, by block name."""
        out = {}
        for w in WALLS3:
            out[f"border_{w}"] = (self.border, self.scale_border, w)
            out[f"laser_{w}"] = (self.laser, self.scale_laser, w)
        return out


def calibrate_three_sided(
    features: TargetFeatures,
    model: OcamModel,
    separation_mm: float,
    layout: TargetLayout | None = None,
) -> SystemCalibration:
    """`joint` for the three-sided target: method1's closed form, then the robust weighted
    refinement of all unknowns on the three walls' borders and laser lines (with a layout,
    each wall's border at its measured height)."""
    from omnisort_hw.core.extrinsics.method1 import calibrate_method1

    t0 = time.perf_counter()
    start = calibrate_method1(features, model, separation_mm)
    roll, pitch, yaw = camera_angles(start.R_SC)
    l_roll, l_pitch = laser_angles(start.laser_normal)
    x0 = np.array(
        [
            roll,
            pitch,
            yaw,
            l_roll,
            l_pitch,
            start.laser_distance_mm,
            start.target["wall_left_x_mm"],
            start.target["border_z_mm"],
            start.target["far_wall_y_mm"],
        ]
    )
    border = {w: model.pixel_to_ray(features.walls[w].border_px) for w in WALLS3}
    laser = {w: model.pixel_to_ray(features.walls[w].laser_px) for w in WALLS3}
    steps = (0.0, 0.0, 0.0)
    if layout is not None and all(w in layout.walls for w in WALLS3):
        left, right, far = (layout.border_offset_mm(w) for w in WALLS3)
        steps = (left, right, far)
    prob = ThreeSidedProblem(border, laser, model, separation_mm, steps)
    sol, noise = _refine(prob, x0)
    p = sol.x
    std, residuals, calib_std = _outcome(prob, sol, noise)
    calib = SystemCalibration(
        model=model,
        R_SC=camera_rotation(p[0], p[1], p[2]),
        laser_normal=laser_normal(p[3], p[4]),
        laser_distance_mm=float(p[5]),
        method="joint",
        target={
            "kind": features.kind,
            "separation_mm": separation_mm,
            "wall_left_x_mm": float(p[6]),
            "wall_right_x_mm": float(p[6] + separation_mm),
            "far_wall_y_mm": float(p[8]),
            "border_z_mm": float(p[7]),
        },
        residuals=residuals,
        std={**calib_std, "far_wall_y_mm": float(std[8])},
        covariance=fit_covariance(prob, sol, model).to_json(),
    )
    calib.elapsed_s = time.perf_counter() - t0
    return calib
