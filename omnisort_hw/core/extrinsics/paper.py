"""`paper`: the published method, a chain of one-dimensional minimisations.

Each step minimises one measure over one angle (bounded Brent search), the other angles held,
with the extracted pixels projected onto a horizontal plane (for the laser: onto a plane
parallel to the candidate laser plane):

1. the two border lines AB and DC parallel,
2. the border lines parallel to Y,
3. their ends lined up (A level with D, B with C),
4. the two laser segments parallel,
5. the laser segments' ends lined up,
6. the measured separation of the laser segments equal to D (sets the distance d).

The paper names the angle of each step in its own frame. In this project's frame (docs/frames.md:
roll about X, pitch about Y along the walls, yaw about Z) the measures control, in order:
camera roll, camera yaw, camera pitch, laser roll, laser pitch, laser distance; a rotation
about the wall direction leaves the projected borders parallel, which is why pitch comes from
the ends. The chain is repeated (at most `passes` times) until no angle moves by more than
0.001 degree, since each step is solved with the later angles still at their old values.

With a measured target description (`core.target_layout`), steps 3 and 5 line the ends up
where the description puts them: a marker measured d mm further along the left wall than its
partner on the right one is expected d mm further in the projection too (scaled, as the
projection is, by the walls' projected separation over their measured separation).
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.joint import observations
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration, place_side_walls
from omnisort_hw.core.features import TargetFeatures
from omnisort_hw.core.frames import (
    camera_rotation,
    great_circle_normal,
    laser_normal,
    rays_to_plane,
)
from omnisort_hw.core.target_layout import (
    TargetLayout,
    image_centroid_shift,
    side_marker_centres,
)

BOUND = np.radians(20.0)
SIDES = ("left", "right")


def _project_horizontal(rays_S: np.ndarray) -> np.ndarray:
    """Central projection onto the horizontal plane Z = -1 (X, Y)."""
    return rays_S[:, :2] / -rays_S[:, 2:3]


def _direction(points: np.ndarray) -> np.ndarray:
    """Principal direction of 2D points, oriented towards +Y."""
    c = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    v = vt[0]
    return v if v[1] >= 0 else -v


def _angle_between(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.arctan2(a[0] * b[1] - a[1] * b[0], a @ b))


def _minimise(fun: object, x0: float) -> float:
    res = minimize_scalar(
        fun, bounds=(x0 - BOUND, x0 + BOUND), method="bounded", options={"xatol": 1e-7}
    )
    return float(res.x)


def _laser_ends(
    laser_rays: np.ndarray,
    marker_near: np.ndarray,
    marker_far: np.ndarray,
    floor_near: np.ndarray,
    floor_far: np.ndarray,
) -> np.ndarray:
    """Rays where a wall's laser line crosses the vertical marker lines at its two ends."""
    m_laser = great_circle_normal(laser_rays)
    ends = []
    for top, bottom in ((marker_near, floor_near), (marker_far, floor_far)):
        m_vertical = np.cross(top, bottom)
        r = np.cross(m_laser, m_vertical)
        r /= np.linalg.norm(r)
        ends.append(r if r @ (top + bottom) > 0 else -r)
    return np.array(ends)


class _Chain:
    """The measures of the chain, each a function of the angles it is minimised over."""

    def __init__(
        self,
        obs: Any,
        ends: dict[str, np.ndarray],
        stagger: dict[str, float] | None = None,
        separation: float = 1.0,
    ) -> None:
        self.obs = obs
        self.ends = ends
        # per marker name: how much further along (mm) the left wall's marker is than the
        # right wall's (0 for the symmetric target), and per laser end (near, far) the same
        self.stagger = stagger or {}
        self.separation = separation

    def _borders(self, r: float, p: float, y: float) -> list[np.ndarray]:
        R = camera_rotation(r, p, y)
        return [_project_horizontal(self.obs.border[s] @ R.T) for s in SIDES]

    def borders_parallel(self, r: float, p: float, y: float) -> float:
        a, b = (_direction(pts) for pts in self._borders(r, p, y))
        return abs(_angle_between(a, b))

    def borders_along_y(self, r: float, p: float, y: float) -> float:
        axis = np.array([0.0, 1.0])
        return sum(abs(_angle_between(_direction(b), axis)) for b in self._borders(r, p, y))

    def ends_mismatch(self, r: float, p: float, y: float) -> float:
        R = camera_rotation(r, p, y)
        c = {k: _project_horizontal((R @ v)[None, :])[0] for k, v in self.obs.markers.items()}
        names = ("border_near", "border_far", "floor_near", "floor_far")
        total = 0.0
        for nm in names:
            scale = (c[("right", nm)][0] - c[("left", nm)][0]) / self.separation
            want = self.stagger.get(nm, 0.0) * scale
            total += (c[("left", nm)][1] - c[("right", nm)][1] - want) ** 2
        return float(total)

    @staticmethod
    def plane_coords(R: np.ndarray, lr: float, lp: float, rays: np.ndarray) -> np.ndarray:
        """Project rays onto a plane parallel to the candidate laser plane; return their (X, Y)
        in S. The plane is a graph over X-Y, so "ends lined up" reads as equal Y, as for the
        borders, and the true laser lines project parallel to Y."""
        n = laser_normal(lr, lp)
        pts = rays @ R.T
        pts = pts / -(pts @ n)[:, None]
        return pts[:, :2]

    def lasers_parallel(self, R: np.ndarray, lr: float, lp: float) -> float:
        a, b = (_direction(self.plane_coords(R, lr, lp, self.obs.laser[s])) for s in SIDES)
        return abs(_angle_between(a, b))

    def laser_ends_mismatch(self, R: np.ndarray, lr: float, lp: float) -> float:
        e = {s: self.plane_coords(R, lr, lp, self.ends[s]) for s in SIDES}
        scale = (e["right"][:, 0] - e["left"][:, 0]) / self.separation
        want = np.array([self.stagger.get("near", 0.0), self.stagger.get("far", 0.0)]) * scale
        return float(np.sum((e["left"][:, 1] - e["right"][:, 1] - want) ** 2))


def _stagger(layout: TargetLayout | None, obs: Any, ends: dict[str, np.ndarray]) -> dict:
    """Per marker name the left marker's position along the wall minus the right one's (mm),
    and per end ("near", "far") the same for the laser's end: the point of the line from the
    end's border marker to its floor marker where the laser crosses it (its fraction of the
    way down measured as an angle in the image), so a slanting marker pair is followed."""
    if layout is None:
        return {}
    out: dict[str, float] = {}
    for n in layout.walls["left"].markers:
        out[n] = (
            layout.walls["left"].markers[n].along_mm - layout.walls["right"].markers[n].along_mm
        )
    for i, end in enumerate(("near", "far")):
        at = []
        for side in SIDES:
            m = layout.walls[side].markers
            top, low = obs.markers[(side, f"border_{end}")], obs.markers[(side, f"floor_{end}")]
            r = ends[side][i]
            t = np.arccos(np.clip(top @ r, -1, 1)) / np.arccos(np.clip(top @ low, -1, 1))
            at.append((1 - t) * m[f"border_{end}"].along_mm + t * m[f"floor_{end}"].along_mm)
        out[end] = float(at[0] - at[1])
    return out


def _chain(
    obs: Any, layout: TargetLayout | None, separation_mm: float, passes: int
) -> tuple[np.ndarray, np.ndarray]:
    """The chain of one-dimensional minimisations: camera rotation and laser normal."""
    mk = obs.markers
    ends = {
        s: _laser_ends(
            obs.laser[s],
            mk[(s, "border_near")],
            mk[(s, "border_far")],
            mk[(s, "floor_near")],
            mk[(s, "floor_far")],
        )
        for s in SIDES
    }
    chain = _Chain(obs, ends, _stagger(layout, obs, ends), separation_mm)
    roll = pitch = yaw = l_roll = l_pitch = 0.0
    for _ in range(passes):
        before = np.array([roll, pitch, yaw, l_roll, l_pitch])
        roll = _minimise(lambda r, p=pitch, y=yaw: chain.borders_parallel(r, p, y), roll)
        yaw = _minimise(lambda y, r=roll, p=pitch: chain.borders_along_y(r, p, y), yaw)
        pitch = _minimise(lambda p, r=roll, y=yaw: chain.ends_mismatch(r, p, y), pitch)
        R = camera_rotation(roll, pitch, yaw)
        l_roll = _minimise(lambda lr, R=R, lp=l_pitch: chain.lasers_parallel(R, lr, lp), l_roll)
        l_pitch = _minimise(
            lambda lp, R=R, lr=l_roll: chain.laser_ends_mismatch(R, lr, lp), l_pitch
        )
        moved = np.abs(np.array([roll, pitch, yaw, l_roll, l_pitch]) - before)
        if moved.max() < np.radians(1e-3):
            break
    return camera_rotation(roll, pitch, yaw), laser_normal(l_roll, l_pitch)


def _marker_centres(
    obs: Any, layout: TargetLayout, keys: list, R: np.ndarray, separation_mm: float
) -> np.ndarray:
    """The markers' centres in S at the pose R: walls placed by their borders (the known
    separation sets the scale), markers at their described places along and up the walls,
    the walls' near end where the markers' rays put it."""
    left, right = (great_circle_normal(obs.border[s]) for s in SIDES)
    x_left, z_b = place_side_walls(R, left, right, separation_mm)
    walls = {"left": x_left, "right": x_left + separation_mm}
    offsets = layout.marker_offsets(keys)
    hit = [
        rays_to_plane((R @ obs.markers[k])[None, :], np.array([1.0, 0.0, 0.0]), walls[k[0]])[0]
        for k in keys
    ]
    y0 = float(np.mean([p[1] for p in hit] - offsets[:, 0]))
    return side_marker_centres(keys, offsets, walls, y0, z_b)


def calibrate_paper(
    features: TargetFeatures,
    model: OcamModel,
    separation_mm: float,
    layout: TargetLayout | None = None,
    passes: int = 5,
) -> SystemCalibration:
    """The published chain; `layout`: the target as measured (its separation is then used),
    else the symmetric paper target."""
    t0 = time.perf_counter()
    if layout is not None:
        separation_mm = layout.separation_mm
    obs = observations(features, model)
    R, n = _chain(obs, layout, separation_mm, passes)
    sizes = None if layout is None else layout.marker_sizes(sorted(obs.markers))
    if layout is not None and sizes is not None:
        # blob centroids against the centroids of the markers' images at the chain's pose
        keys = sorted(obs.markers)
        observed = model.ray_to_pixel(np.array([obs.markers[k] for k in keys]))
        for _ in range(2):
            centres = _marker_centres(obs, layout, keys, R, separation_mm)
            shift = image_centroid_shift(model, R, centres, sizes)
            rays = model.pixel_to_ray(observed - shift)
            obs = replace(obs, markers=dict(zip(keys, rays, strict=True)))
            R, n = _chain(obs, layout, separation_mm, passes)

    def separation_error(d: float) -> float:
        pts = {}
        for s in SIDES:
            rays = obs.laser[s] @ R.T
            t = -d * n[2] / (rays @ n)
            pts[s] = rays * t[:, None]
        return (np.mean(pts["right"][:, 0]) - np.mean(pts["left"][:, 0]) - separation_mm) ** 2

    res = minimize_scalar(
        separation_error, bounds=(10.0, 20000.0), method="bounded", options={"xatol": 1e-6}
    )
    calib = SystemCalibration(
        model=model,
        R_SC=R,
        laser_normal=n,
        laser_distance_mm=float(res.x),
        method="paper",
        target={"kind": features.kind, "separation_mm": separation_mm},
        residuals={"separation_error_mm": float(np.sqrt(res.fun))},
    )
    calib.elapsed_s = time.perf_counter() - t0
    return calib
