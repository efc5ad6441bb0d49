"""Ground truth written beside every rendered image (`NAME.truth.json`).

The keys shared with `system.json` (docs/architecture.md) come first: `camera`, `camera_rotation`,
`laser_plane`, `target`, `robot_base`; then what only a simulator knows: cube poses (S and B),
pixel positions of every checkerboard corner and target marker, and the laser/scene
intersection polylines in S (exact straight pieces) and in pixels (densely projected).
Points are projected through the same camera model the renderer uses; a point counts as
visible when it faces the camera, lies inside the lens circle and nothing hides it.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.frames import camera_angles, invert_pose, rpy_deg
from sim_backend.laser import LaserPlane, laser_polylines, visible_from
from sim_backend.world import SimWorld

TRUTH_FORMAT = "omnisort-sim-truth/1"
PX_POLYLINE_STEP = 1.5


@dataclass(frozen=True)
class Projector:
    """Projects points of S into the image through R_SC and the camera model."""

    model: OcamModel
    R_SC: np.ndarray
    theta_circle: float

    def to_camera(self, pts: np.ndarray) -> np.ndarray:
        """Points (..., 3) of S in the camera frame C."""
        return np.asarray(pts, float) @ self.R_SC

    def project(self, pts: np.ndarray) -> np.ndarray:
        """Pixels (..., 2) of points (..., 3) in S."""
        return self.model.ray_to_pixel(self.to_camera(pts))

    def in_view(self, pts: np.ndarray) -> np.ndarray:
        """Inside the lens circle and the image."""
        c = self.to_camera(pts)
        theta = self.model.angle_from_axis(c)
        return (theta <= self.theta_circle) & self.model.in_view(c)

    @classmethod
    def for_world(cls, world: SimWorld, model: OcamModel) -> Projector:
        """The projector of a world's camera."""
        circle = np.deg2rad(world.scene.camera.image_circle_fov_deg) / 2.0
        return cls(model, world.R_SC, min(circle, model.theta_max))


def _visible(world: SimWorld, proj: Projector, pts: np.ndarray, normal: np.ndarray) -> np.ndarray:
    ok = ((-pts) @ normal > 0) & proj.in_view(pts)
    idx = np.flatnonzero(ok)
    if idx.size:
        ok[idx] = visible_from(world.client, np.zeros(3), pts[idx])
    return ok


def _r(values: ArrayLike, nd: int = 4) -> list[Any]:
    return np.round(np.asarray(values, float), nd).tolist()


def _densify_px(proj: Projector, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The projected curve of segment a-b, points about PX_POLYLINE_STEP px apart."""
    length = float(np.linalg.norm(b - a))
    n = max(2, int(np.ceil(length / 0.5)) + 1)
    pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
    px = proj.project(pts)
    step = np.linalg.norm(np.diff(px, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(step)])
    marks = np.arange(0.0, arc[-1], PX_POLYLINE_STEP)
    keep = np.unique(np.concatenate([np.searchsorted(arc, marks), [n - 1]]))
    return px[keep]


def _pose_dict(T: np.ndarray) -> dict[str, Any]:
    roll, pitch, yaw = rpy_deg(T[:3, :3])
    return {"matrix": _r(T, 6), "xyz_mm": _r(T[:3, 3]), "rpy_deg": _r([roll, pitch, yaw], 6)}


def mounting_truth(world: SimWorld, laser_on: bool) -> dict[str, Any]:
    """The camera's rotation in S and the laser plane, as system.json holds them."""
    las = world.scene.laser
    roll, pitch, yaw = np.degrees(camera_angles(world.R_SC))
    return {
        "camera_rotation": {  # as it is now: mounted, or knocked, since the scene was loaded
            "roll_deg": round(float(roll), 9),
            "pitch_deg": round(float(pitch), 9),
            "yaw_deg": round(float(yaw), 9),
            "matrix": _r(world.R_SC, 12),
        },
        "laser_plane": {  # as it is now: the scene's, or as the simulator's panel set it
            "roll_deg": float(world.laser_angles_deg[0]),
            "pitch_deg": float(world.laser_angles_deg[1]),
            "distance_mm": world.laser_distance,
            "normal": _r(world.laser_normal, 12),
            "on": bool(laser_on),
            "width_mm": las.width_mm,
        },
    }


def build_truth(
    world: SimWorld,
    model: OcamModel,
    laser_on: bool,
    seed: int | None = None,
    degraded: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The truth dict of the world's current state (image fields are added when written)."""
    scene = world.scene
    cam = scene.camera
    proj = Projector.for_world(world, model)
    plane = LaserPlane(world.laser_normal, world.laser_distance)
    truth: dict[str, Any] = {
        "format": TRUTH_FORMAT,
        "scene": {"name": scene.name, "description": scene.scene.description},
        "camera": {**model.to_dict(), "image_circle_fov_deg": cam.image_circle_fov_deg},
        **mounting_truth(world, laser_on),
        "floor_z_mm": world.floor_z,
        "target": _target_truth(world),
        "robot_base": None,
        "cubes": [],
        "markers_px": [],
        "checkerboards": [],
        "checkerboards_partial": [],
        "laser_polylines_S": [],
        "laser_polylines_px": [],
        "seed": seed,
        "degraded": degraded,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    T_S_B = world.T_S_B
    T_B_S = invert_pose(T_S_B) if T_S_B is not None else None
    if T_S_B is not None and scene.robot is not None:
        truth["robot_base"] = {**_pose_dict(T_S_B), "model": scene.robot.model}
    for i, (cube, body) in enumerate(world.info.cubes):
        T = world.body_pose(body)
        item: dict[str, Any] = {
            "index": i,
            "colour": cube.color.name,
            "rgb": list(cube.color.rgb),
            "size_mm": cube.size_mm,
            "center_S_mm": _r(T[:3, 3]),
            "yaw_deg": round(rpy_deg(T[:3, :3])[2], 6),
            "pose_S": _r(T, 6),
            "center_px": _r(proj.project(T[:3, 3])),
        }
        if T_B_S is not None:
            TB = T_B_S @ T
            item.update({"pose_B": _r(TB, 6), "center_B_mm": _r(TB[:3, 3])})
        truth["cubes"].append(item)
    for m in world.info.markers:
        wall = next(w for w in world.info.walls if w["name"] == m.wall)
        vis = _visible(
            world, proj, np.vstack([m.center[None], m.corners]), np.asarray(wall["normal"])
        )
        truth["markers_px"].append(
            {
                "wall": m.wall,
                "name": m.name,
                "letter": m.letter,
                "center_px": _r(proj.project(m.center)),
                "corners_px": _r(proj.project(m.corners)),
                "visible": bool(vis.all()),
            }
        )
    for board in world.info.boards:
        vis = _visible(world, proj, board.corners, board.rect.normal)
        item = {
            "name": board.name,
            "inner_corners": list(board.inner_corners),
            "square_mm": board.square_mm,
            "corners_px": _r(proj.project(board.corners)),
            "corners_S_mm": _r(board.corners),
            "pose_S": _r(board.pose, 6),
            "on_floor": board.on_floor,
        }
        if T_B_S is not None:
            item["pose_B"] = _r(T_B_S @ board.pose, 6)
        if vis.all():
            truth["checkerboards"].append(item)
        elif vis.any():
            item["corners_visible"] = vis.tolist()
            truth["checkerboards_partial"].append(item)
    if laser_on:
        for line in laser_polylines(world, plane, proj.in_view):
            a, b = line.points[0], line.points[-1]
            truth["laser_polylines_S"].append({"surface": line.surface, "points_mm": _r([a, b])})
            truth["laser_polylines_px"].append(
                {"surface": line.surface, "points_px": _r(_densify_px(proj, a, b))}
            )
    return truth


def _target_truth(world: SimWorld) -> dict[str, Any] | None:
    t = world.target_spec
    if t is None:
        return None
    return {
        "kind": t.kind,
        "separation_mm": t.separation_mm,
        "length_mm": t.length_mm,
        "center_mm": list(t.center_mm),
        "yaw_deg": t.yaw_deg,
        "wall_height_mm": t.wall_height_mm,
        "wall_thickness_mm": t.wall_thickness_mm,
        "border_height_mm": t.border_height_mm,
        "marker_size_mm": t.marker_size_mm,
        "floor_z_mm": world.floor_z,
        "walls": [
            {
                "name": w["name"],
                "inner_face_origin_mm": _r(w["inner_face_origin_mm"]),
                "along_wall": _r(w["along_wall"], 9),
                "normal": _r(w["normal"], 9),
                "length_mm": w["length_mm"],
                "border_segment_S_mm": _r(w["border_segment_S_mm"]),
            }
            for w in world.info.walls
        ],
        "markers": [
            {
                "wall": m.wall,
                "name": m.name,
                "letter": m.letter,
                "center_S_mm": _r(m.center),
                "corners_S_mm": _r(m.corners),
            }
            for m in world.info.markers
        ],
    }
