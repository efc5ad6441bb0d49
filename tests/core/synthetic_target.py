"""Synthetic two-sided / three-sided target features from known geometry (test helper)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.checkerboard import BoardSpec
from omnisort_hw.core.features import BoardFeatures, BoardsFeatures, TargetFeatures, WallFeatures
from omnisort_hw.core.frames import camera_rotation, laser_normal


@dataclass
class Scene:
    angles_deg: dict[str, float]
    separation: float = 1084.5
    length: float = 1084.5
    floor_z: float = -1250.0
    border_z: float = -650.0
    y_near: float = 120.0
    marker_top_z: float = -650.0
    marker_floor_z: float = -1200.0

    @property
    def R(self) -> np.ndarray:
        a = np.radians
        return camera_rotation(
            a(self.angles_deg["cam_roll_deg"]),
            a(self.angles_deg["cam_pitch_deg"]),
            a(self.angles_deg["cam_yaw_deg"]),
        )

    @property
    def normal(self) -> np.ndarray:
        a = np.radians
        return laser_normal(
            a(self.angles_deg["laser_roll_deg"]), a(self.angles_deg["laser_pitch_deg"])
        )

    @property
    def d(self) -> float:
        return self.angles_deg["laser_distance_mm"]


def random_angles(rng: np.random.Generator, spread: float = 10.0) -> dict[str, float]:
    keys = ("cam_roll_deg", "cam_pitch_deg", "cam_yaw_deg", "laser_roll_deg", "laser_pitch_deg")
    out = {k: float(rng.uniform(-spread, spread)) for k in keys}
    out["laser_distance_mm"] = float(rng.uniform(800, 1100))
    return out


def project(model: OcamModel, R: np.ndarray, pts_S: np.ndarray) -> np.ndarray:
    return model.ray_to_pixel(pts_S @ R)  # rows: R^T p


def side_wall_features(
    model: OcamModel, sc: Scene, rng: np.random.Generator, noise: float, n_pts: int = 120
) -> dict[str, WallFeatures]:
    walls = {}
    y0, y1 = sc.y_near, sc.y_near + sc.length
    n, d = sc.normal, sc.d
    for side, xw in (("left", -sc.separation / 2), ("right", sc.separation / 2)):
        ys = np.linspace(y0 + 30, y1 - 30, n_pts)
        border = np.stack([np.full_like(ys, xw), ys, np.full_like(ys, sc.border_z)], axis=1)
        # laser: n.(p - (0,0,-d)) = 0 with X = xw -> z = -d - (n_x xw + n_y y) / n_z
        lz = -d - (n[0] * xw + n[1] * ys) / n[2]
        laser = np.stack([np.full_like(ys, xw), ys, lz], axis=1)
        markers = {
            "border_near": [xw, y0, sc.marker_top_z],
            "border_far": [xw, y1, sc.marker_top_z],
            "floor_near": [xw, y0, sc.marker_floor_z],
            "floor_far": [xw, y1, sc.marker_floor_z],
        }
        mk = {
            k: project(model, sc.R, np.array([v]))[0] + rng.normal(0, noise * 1.5, 2)
            for k, v in markers.items()
        }
        floor = np.stack([np.full_like(ys, xw), ys, np.full_like(ys, sc.floor_z)], axis=1)
        walls[side] = WallFeatures(
            border_px=project(model, sc.R, border) + rng.normal(0, noise, (n_pts, 2)),
            laser_px=project(model, sc.R, laser) + rng.normal(0, noise, (n_pts, 2)),
            markers_px=mk,
            floor_px=project(model, sc.R, floor) + rng.normal(0, noise, (n_pts, 2)),
        )
    return walls


def two_sided(model: OcamModel, sc: Scene, seed: int = 0, noise: float = 0.2) -> TargetFeatures:
    rng = np.random.default_rng(seed)
    return TargetFeatures("two-sided", model.image_size, side_wall_features(model, sc, rng, noise))


def three_sided(
    model: OcamModel, sc: Scene, seed: int = 0, noise: float = 0.2, n_pts: int = 120
) -> TargetFeatures:
    """The U: side walls as in two_sided, plus a far wall at the far end of the side walls."""
    rng = np.random.default_rng(seed)
    walls = side_wall_features(model, sc, rng, noise, n_pts)
    y_far = sc.y_near + sc.length
    xs = np.linspace(-sc.separation / 2 + 30, sc.separation / 2 - 30, n_pts)
    n, d = sc.normal, sc.d
    border = np.stack([xs, np.full_like(xs, y_far), np.full_like(xs, sc.border_z)], axis=1)
    lz = -d - (n[0] * xs + n[1] * y_far) / n[2]
    laser = np.stack([xs, np.full_like(xs, y_far), lz], axis=1)
    walls["far"] = WallFeatures(
        border_px=project(model, sc.R, border) + rng.normal(0, noise, (n_pts, 2)),
        laser_px=project(model, sc.R, laser) + rng.normal(0, noise, (n_pts, 2)),
    )
    return TargetFeatures("three-sided", model.image_size, walls)


def checkerboards(
    model: OcamModel, sc: Scene, seed: int = 0, noise: float = 0.2, square: float = 97.0
) -> BoardsFeatures:
    """Two vertical 9x6 boards forming an L: 'left' in the plane X = -D/2 (columns along +Y),
    'far' in the plane Y = y_far (columns along +X); rows run downwards."""
    rng = np.random.default_rng(seed)
    spec = BoardSpec(9, 6, square)
    y_far = sc.y_near + sc.length
    top = sc.floor_z + 150 + 5 * square
    frames = {
        "left": (
            np.array([-sc.separation / 2, sc.y_near + 150, top]),
            np.array([0.0, 1.0, 0.0]),
            np.array([0.0, 0.0, -1.0]),
        ),
        "far": (
            np.array([-4 * square, y_far, top]),
            np.array([1.0, 0.0, 0.0]),
            np.array([0.0, 0.0, -1.0]),
        ),
    }
    n, d = sc.normal, sc.d
    boards = {}
    for name, (origin, ex, ey) in frames.items():
        obj = spec.object_points()
        pts = origin + obj[:, :1] * ex + obj[:, 1:2] * ey
        # Laser across the board: points of the board plane on the laser plane.
        s = np.linspace(0, 8 * square, 80)
        base = origin + s[:, None] * ex  # top edge line; walk down ey until the laser plane
        t = (-d * n[2] - base @ n) / (ey @ n)
        lpts = base + t[:, None] * ey
        boards[name] = BoardFeatures(
            name=name,
            inner_corners=(9, 6),
            square_mm=square,
            corners_px=project(model, sc.R, pts) + rng.normal(0, noise, (len(pts), 2)),
            laser_px=project(model, sc.R, lpts) + rng.normal(0, noise, (len(lpts), 2)),
        )
    return BoardsFeatures(model.image_size, boards)
