"""`method2`: two perpendicular vertical checkerboards.

Each board's pose comes from its corners through the camera model (a perspective-n-point
start on the rays, refined on angles between observed and predicted rays). The left board's
normal is X, the far board's normal is Y, and the laser plane is fitted to the laser points,
each cut with the known plane of the board it lies on.
"""

from __future__ import annotations

import time

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.checkerboard import BoardSpec
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration, fit_laser_plane
from omnisort_hw.core.features import BoardsFeatures
from omnisort_hw.core.frames import nearest_rotation, rays_to_plane
from omnisort_hw.errors import CalibrationError


def board_pose(rays: np.ndarray, board_pts: np.ndarray) -> tuple[np.ndarray, float]:
    """Board-to-camera transform from corner rays (N, 3) and board points (N, 3), and the RMS
    angular residual (rad). Works for boards up to the image circle's edge (z may be < 0)."""
    # Start: PnP on a virtual pinhole looking along the mean ray (every corner in front of it).
    axis = rays.mean(axis=0)
    axis /= np.linalg.norm(axis)
    Rv = _look_along(axis)
    local = rays @ Rv.T
    if np.any(local[:, 2] <= 0.05):
        raise CalibrationError("board spans too wide an angle for a pose estimate")
    norm = local[:, :2] / local[:, 2:3]
    ok, rvec, tvec = cv2.solvePnP(
        board_pts.astype(np.float64),
        norm.astype(np.float64),
        np.eye(3),
        None,
        flags=cv2.SOLVEPNP_SQPNP,
    )
    if not ok:
        raise CalibrationError("board pose: PnP failed")
    R0 = Rv.T @ cv2.Rodrigues(rvec)[0]
    t0 = Rv.T @ tvec.ravel()
    x0 = np.concatenate([Rotation.from_matrix(R0).as_rotvec(), t0])

    def residuals(x: np.ndarray) -> np.ndarray:
        pts = board_pts @ Rotation.from_rotvec(x[:3]).as_matrix().T + x[3:]
        pts /= np.linalg.norm(pts, axis=1, keepdims=True)
        return np.cross(rays, pts).ravel()

    sol = least_squares(residuals, x0, method="lm")
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(sol.x[:3]).as_matrix()
    T[:3, 3] = sol.x[3:]
    return T, float(np.sqrt(np.mean(sol.fun**2) * 3 / 2))


def _look_along(axis: np.ndarray) -> np.ndarray:
    """A rotation whose third row is `axis` (camera-to-virtual-view)."""
    helper = np.array([0.0, 1.0, 0.0]) if abs(axis[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, axis)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(axis, x), axis])


def calibrate_method2(features: BoardsFeatures, model: OcamModel) -> SystemCalibration:
    t0 = time.perf_counter()
    poses: dict[str, np.ndarray] = {}
    fit: dict[str, float] = {}
    for name in ("left", "far"):
        if name not in features.boards:
            raise CalibrationError(f"checkerboards: the {name} board was not found")
        b = features.boards[name]
        spec = BoardSpec(b.inner_corners[0], b.inner_corners[1], b.square_mm)
        rays = model.pixel_to_ray(b.corners_px)
        poses[name], fit[name] = board_pose(rays, spec.object_points())
    normals = {k: T[:3, 2] for k, T in poses.items()}
    centres = {k: T[:3, 3] for k, T in poses.items()}
    # X: the left board's normal, pointing from the board towards the camera (into the room).
    x = normals["left"] if normals["left"] @ -centres["left"] > 0 else -normals["left"]
    # Y: the far board's normal, pointing from the camera towards the far board.
    y = normals["far"] if normals["far"] @ centres["far"] > 0 else -normals["far"]
    R = nearest_rotation(np.stack([x, y, np.cross(x, y)]))
    pts = []
    for name in ("left", "far"):
        b = features.boards[name]
        if len(b.laser_px) < 3:
            raise CalibrationError(f"{name} board: no laser line found on it")
        nC = poses[name][:3, 2]
        rays = model.pixel_to_ray(b.laser_px)
        pts.append(rays_to_plane(rays, nC, float(nC @ poses[name][:3, 3])) @ R.T)
    n, d, plane_rms = fit_laser_plane(np.concatenate(pts))
    calib = SystemCalibration(
        model=model,
        R_SC=R,
        laser_normal=n,
        laser_distance_mm=d,
        method="method2",
        target={
            "kind": "checkerboards",
            "boards": {k: {"pose_C": poses[k].tolist()} for k in poses},
        },
        residuals={
            "board_rms_deg": {k: float(np.degrees(v)) for k, v in fit.items()},
            "laser_plane_rms_mm": plane_rms,
            "boards_perpendicularity_deg": float(
                np.degrees(np.arcsin(np.clip(abs(normals["left"] @ normals["far"]), 0, 1)))
            ),
        },
    )
    calib.elapsed_s = time.perf_counter() - t0
    return calib
