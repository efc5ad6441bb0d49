"""`joint` on the three-sided target: the robust weighted refinement of `joint` on the three
walls' borders and laser lines, started from method1's closed form.

Without a target description the far wall supplies what the markers supply on the two-sided
target, so markers are not needed (both marker layouts work), and the three borders are taken
to stand at one height. With a description that gives the markers, the markers the image shows
join the fit at their measured positions (the near markers on the side walls; at the far end,
the far wall's markers when the side walls' own are hidden behind it, as in the published
layout of 8), and each wall's border height becomes free: a border is a printed (or textured)
edge whose imaged height can differ between walls by a millimetre (the authors' renders show
it: texture filtering), which would tilt the walls' common frame by 0.04 degree about the wall
direction; the markers then fix that rotation.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.joint import (
    LineStore,
    _outcome,
    _refine,
    _tangent_basis,
    _WeightedProblem,
)
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration, pixel_scale
from omnisort_hw.core.features import TargetFeatures
from omnisort_hw.core.frames import (
    camera_angles,
    camera_rotation,
    laser_angles,
    laser_normal,
    rays_to_plane,
)
from omnisort_hw.core.target_layout import TargetLayout, image_centroid_shift

WALLS3 = ("left", "right", "far")
_BASE = 9  # camera 3, laser 3, left wall X, border Z, far wall Y


class ThreeSidedProblem(_WeightedProblem):
    """Residuals (pixels) of the three borders and the three laser lines for (camera
    roll/pitch/yaw, laser roll/pitch/distance, left wall X, border height, far wall Y), and,
    with `markers`, of the markers for (walls' near end Y0, right and far border steps)."""

    def __init__(
        self,
        border: dict[str, np.ndarray],
        laser: dict[str, np.ndarray],
        model: OcamModel,
        separation: float,
        border_steps: tuple[float, float, float] = (0.0, 0.0, 0.0),
        markers: dict[tuple[str, str], np.ndarray] | None = None,
        layout: TargetLayout | None = None,
    ) -> None:
        self.border_steps = np.asarray(border_steps, float)
        self.border = dict(border)
        self.laser = dict(laser)
        self.scale_border = {w: pixel_scale(model, r) for w, r in border.items()}
        self.scale_laser = {w: pixel_scale(model, r) for w, r in laser.items()}
        self.separation = separation
        self.weights = {"border": 1.0, "laser": 1.0}
        self.inflation: dict[str, float] = {}
        self.marker_keys = sorted(markers) if markers and layout else []
        if self.marker_keys and layout is not None:
            assert markers is not None
            self.weights["markers"] = 1.0
            self.marker_rays = np.array([markers[k] for k in self.marker_keys])
            self.marker_basis = _tangent_basis(self.marker_rays)
            self.marker_scale = pixel_scale(model, self.marker_rays)
            left = layout.walls["left"].border_height_mm
            spec = [layout.walls[w].markers[n] for w, n in self.marker_keys]
            self.marker_along = np.array([m.along_mm for m in spec])
            self.marker_up = np.array([m.height_mm - left for m in spec])
            self.marker_wall = np.array([WALLS3.index(w) for w, _ in self.marker_keys])

    def marker_centres(self, p: np.ndarray) -> np.ndarray:
        """(K, 3) centres in S of the markers in `marker_keys` order."""
        x_left, z_b, y_far, y0 = p[6], p[7], p[8], p[9]
        side_x = np.where(self.marker_wall == 1, x_left + self.separation, x_left)
        far = self.marker_wall == 2
        x = np.where(far, x_left + self.marker_along, side_x)
        y = np.where(far, y_far, y0 + self.marker_along)
        return np.stack([x, y, z_b + self.marker_up], axis=1)

    def normals_S(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Great-circle normals in S of the borders and laser lines, rows in WALLS3 order."""
        n = laser_normal(p[3], p[4])
        d, x_left, z_b, y_far = p[5], p[6], p[7], p[8]
        xs = np.array([x_left, x_left + self.separation])
        zb = z_b + self.border_steps  # each wall's border height above the left one's
        if self.marker_keys:
            zb = zb + np.array([0.0, p[10], p[11]])
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
        """Signed distances (px) of every border and laser point from its model line, and of
        every marker from its model position (two components each)."""
        R = camera_rotation(p[0], p[1], p[2])
        border, laser = (m @ R for m in self.normals_S(p))
        out = {}
        for i, w in enumerate(WALLS3):
            out[f"border_{w}"] = (self.border[w] @ border[i]) * self.scale_border[w]
            out[f"laser_{w}"] = (self.laser[w] @ laser[i]) * self.scale_laser[w]
        if self.marker_keys:
            dirs = self.marker_centres(p) @ R
            dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
            out["markers"] = (
                np.einsum("nkj,nj->nk", self.marker_basis, dirs) * self.marker_scale[:, None]
            ).ravel()
        return out

    def line_store(self) -> LineStore:
        """Border and laser rays and scales of each wall, by block name."""
        out = {}
        for w in WALLS3:
            out[f"border_{w}"] = (self.border, self.scale_border, w)
            out[f"laser_{w}"] = (self.laser, self.scale_laser, w)
        return out


def _marker_rays(
    features: TargetFeatures, model: OcamModel, layout: TargetLayout | None
) -> dict[tuple[str, str], np.ndarray]:
    """The markers the image shows, keyed by (the wall they stand on, their name in the
    layout); empty when the layout does not describe them all."""
    if layout is None or any(w not in layout.walls for w in WALLS3):
        return {}
    own_far = bool(features.walls["far"].markers_px)
    where: dict[tuple[str, str], tuple[str, str]] = {}
    for side, far_end in (("left", "near"), ("right", "far")):
        for name in features.walls[side].markers_px:
            if name.endswith("far") and not own_far:
                # published layout: at the far end the image shows the far wall's markers
                where[(side, name)] = ("far", f"{name.split('_')[0]}_{far_end}")
            else:
                where[(side, name)] = (side, name)
    for name in features.walls["far"].markers_px:
        where[("far", name)] = ("far", name)
    out = {}
    for (wall, name), key in where.items():
        if key[1] not in layout.walls[key[0]].markers:
            return {}
        uv = np.asarray(features.walls[wall].markers_px[name], float)
        out[key] = model.pixel_to_ray(uv[None, :])[0]
    return out


def _start(
    start: SystemCalibration, markers: dict[tuple[str, str], np.ndarray], layout: TargetLayout
) -> list[float]:
    """Y0 from the side walls' markers cut with their wall planes, border steps 0."""
    t = start.target
    xs = {"left": t["wall_left_x_mm"], "right": t["wall_left_x_mm"] + t["separation_mm"]}
    y0 = [
        rays_to_plane((start.R_SC @ ray)[None, :], np.array([1.0, 0.0, 0.0]), xs[w])[0][1]
        - layout.walls[w].markers[n].along_mm
        for (w, n), ray in markers.items()
        if w != "far"
    ]
    return [float(np.mean(y0)) if y0 else 0.0, 0.0, 0.0]


def _visible(
    centres: np.ndarray, sizes: np.ndarray, far: np.ndarray, x_left: float, prob: Any
) -> tuple[np.ndarray, np.ndarray]:
    """The parts of the markers the camera sees: a far-wall marker reaching past a side wall's
    inner face (the published layout puts them in the corners) is hidden there by that wall,
    the camera standing between the walls."""
    lo = np.maximum(centres[:, 0] - 0.5 * sizes[:, 0], x_left)
    hi = np.minimum(centres[:, 0] + 0.5 * sizes[:, 0], x_left + prob.separation)
    clipped = far & (hi > lo)
    out, out_sizes = centres.copy(), sizes.copy()
    out[clipped, 0] = 0.5 * (lo + hi)[clipped]
    out_sizes[clipped, 0] = (hi - lo)[clipped]
    return out, out_sizes


def _with_centroids(
    prob: ThreeSidedProblem,
    sol: Any,
    noise: dict[str, float],
    model: OcamModel,
    layout: TargetLayout,
    make: Any,
) -> tuple[Any, ThreeSidedProblem, dict[str, float]]:
    """The marker blobs' centroids compared with their rectangles' imaged centroids (see
    `joint._solve`), when the layout gives every marker's size."""
    specs = [layout.walls[w].markers[n] for w, n in prob.marker_keys]
    if not prob.marker_keys or any(m.size_mm is None for m in specs):
        return sol, prob, noise
    sizes = np.array([m.size_mm for m in specs], float)
    axis = np.where(prob.marker_wall == 2, 0, 1)
    observed = model.ray_to_pixel(prob.marker_rays)
    shift = np.zeros_like(observed)
    for _ in range(3):
        R = camera_rotation(*sol.x[:3])
        centres = prob.marker_centres(sol.x)
        visible, vis_sizes = _visible(centres, sizes, prob.marker_wall == 2, sol.x[6], prob)
        new = image_centroid_shift(model, R, visible, vis_sizes, axis, centres)
        if np.max(np.abs(new - shift)) < 0.005:
            break
        shift = new
        rays = model.pixel_to_ray(observed - shift)
        prob = make(dict(zip(prob.marker_keys, rays, strict=True)))
        sol, noise = _refine(prob, sol.x)
    return sol, prob, noise


def calibrate_three_sided(
    features: TargetFeatures,
    model: OcamModel,
    separation_mm: float,
    layout: TargetLayout | None = None,
) -> SystemCalibration:
    """`joint` for the three-sided target (module docstring); `layout` the target as measured."""
    from omnisort_hw.core.extrinsics.method1 import calibrate_method1

    t0 = time.perf_counter()
    start = calibrate_method1(features, model, separation_mm)
    roll, pitch, yaw = camera_angles(start.R_SC)
    l_roll, l_pitch = laser_angles(start.laser_normal)
    x0 = [
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
    border = {w: model.pixel_to_ray(features.walls[w].border_px) for w in WALLS3}
    laser = {w: model.pixel_to_ray(features.walls[w].laser_px) for w in WALLS3}
    steps = (0.0, 0.0, 0.0)
    if layout is not None and all(w in layout.walls for w in WALLS3):
        steps = tuple(layout.border_offset_mm(w) for w in WALLS3)
    markers = _marker_rays(features, model, layout)

    def make(m: dict[tuple[str, str], np.ndarray]) -> ThreeSidedProblem:
        return ThreeSidedProblem(border, laser, model, separation_mm, steps, m, layout)

    prob = make(markers)
    if prob.marker_keys and layout is not None:
        x0 += _start(start, markers, layout)
    sol, noise = _refine(prob, np.array(x0))
    if prob.marker_keys and layout is not None:
        sol, prob, noise = _with_centroids(prob, sol, noise, model, layout, make)
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
        residuals={**residuals, "markers_used": len(prob.marker_keys)},
        std={**calib_std, "far_wall_y_mm": float(std[8])},
    )
    calib.elapsed_s = time.perf_counter() - t0
    return calib
