"""Robot registration: the UR base pose T_SB from the floor checkerboard in one fisheye image.

The checkerboard lies on the floor at a known, fixed pose in the robot base frame B
(`T_B_board`, the cell's "offset"). Its pose in S comes from its corners: a virtual top-down
perspective view of the floor (through the camera model and R_SC) makes the small, distorted
board look like an ordinary checkerboard for detection; the corners are then refined by fitting
the whole blurred pattern in a finer top-down view around the board and mapped back to the
fisheye image; their rays give the board pose in C (`method2.board_pose`), rotated into S
with the calibrated R_SC, and refined on the corner rays with a prior that the floor is level
in S, as strong as the camera rotation is sure (exactly level, free, or in between). Then
T_SB = T_S_board . inv(T_B_board).

Board frame (the same as the simulator's truth `checkerboards[].pose_*`): origin at the first
inner corner, x along the first row of corners, y along the first column (towards the next
row), z = x cross y, into the printed face (down for a floor board). The first inner corner is
the one diagonally next to the black outer-corner square on the side where, seen from the
front, the rows run clockwise from x to y. Boards must have cols + rows odd (e.g. 9x6), so
that the pattern is not symmetric under a half turn and the first corner is unique.

The offset is `X, Y, Z, RX, RY, RZ`: the board frame in B, millimetres and degrees, rotation
Rz(RZ) Ry(RY) Rx(RX) (the project's Z-Y-X order), i.e. T_B_board. A floor board printed face
up has RX = 180 (its z points down); the shipped sorting scene's board is
`200, -180, 2, 180, 0, 90`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation
from scipy.special import erf

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.checkerboard import BoardSpec, Detector, detect_corners, to_gray
from omnisort_hw.core.extrinsics.method2 import board_pose
from omnisort_hw.core.frames import invert_pose, rot_z, rpy_deg, rpy_matrix
from omnisort_hw.errors import CalibrationError, FeatureNotFoundError, InputError

# Virtual view: field of the top-down view (half angle from the nadir) and its magnification
# relative to the fisheye's pixel density at the centre (the view is cut into a few tiles).
VIEW_HALF_ANGLE_DEG = 62.0
VIEW_MAGNIFICATION = 1.1
# Magnification of the view the corners are refined in (relative to the fisheye's centre).
FINE_MAGNIFICATION = 1.0
# Corner 1-sigma never assumed below this (px): resampling and rendering leave ~0.05 px of
# error that the pattern fit's own residuals do not show (measured against the truth).
CORNER_NOISE_FLOOR_PX = 0.05
# Largest tilt (deg) between the freely fitted board and the level floor before we refuse.
MAX_LEVEL_TILT_DEG = 3.0


def pose_from_offset(offset: tuple[float, ...] | np.ndarray) -> np.ndarray:
    """T (4x4) from X, Y, Z mm and RX, RY, RZ deg with R = Rz(RZ) Ry(RY) Rx(RX)."""
    vals = np.asarray(offset, float).reshape(-1)
    if vals.shape != (6,) or not np.all(np.isfinite(vals)):
        raise InputError(f"offset must be 6 finite numbers X,Y,Z,RX,RY,RZ, got {offset!r}")
    rx, ry, rz = np.radians(vals[3:])
    T = np.eye(4)
    T[:3, :3] = rpy_matrix(rx, ry, rz)
    T[:3, 3] = vals[:3]
    return T


def pose_record(T: np.ndarray) -> dict[str, Any]:
    """{matrix, xyz_mm, rpy_deg} as in system.json / truth.json."""
    return {
        "matrix": np.round(T, 9).tolist(),
        "xyz_mm": np.round(T[:3, 3], 4).tolist(),
        "rpy_deg": [round(v, 6) for v in rpy_deg(T[:3, :3])],
    }


def pose_error(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """Translation error (mm) and rotation angle between two poses (deg)."""
    dt = float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]))
    R = Rotation.from_matrix(T_est[:3, :3].T @ T_true[:3, :3])
    return dt, float(np.degrees(R.magnitude()))


# ---- detection ------------------------------------------------------------------------------


@dataclass(frozen=True)
class TopView:
    """A virtual pinhole looking straight down in S (x_V = X_S, y_V = -Y_S) and its remap."""

    f_px: float
    origin_uv: tuple[float, float]  # the virtual pixel of the nadir, in this tile's pixels
    size: tuple[int, int]

    def rays_S(self, uv: np.ndarray) -> np.ndarray:
        """Unit rays in S of virtual pixels (N, 2)."""
        uv = np.asarray(uv, float).reshape(-1, 2)
        d = np.stack(
            [
                (uv[:, 0] - self.origin_uv[0]) / self.f_px,
                -(uv[:, 1] - self.origin_uv[1]) / self.f_px,
                -np.ones(len(uv)),
            ],
            axis=1,
        )
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def render(self, image: np.ndarray, model: OcamModel, R_SC: np.ndarray) -> np.ndarray:
        """The fisheye image resampled into this view (bilinear)."""
        w, h = self.size
        us, vs = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
        rays = self.rays_S(np.stack([us.ravel(), vs.ravel()], axis=1)) @ R_SC
        px = model.ray_to_pixel(rays).astype(np.float32).reshape(h, w, 2)
        return cv2.remap(
            image, px[..., 0], px[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT
        )


def _centre_density(model: OcamModel) -> float:
    """Pixels per radian of the fisheye near its optical axis."""
    eps = 1e-3
    px = model.ray_to_pixel(np.array([[0.0, 0.0, 1.0], [np.sin(eps), 0.0, np.cos(eps)]]))
    return float(np.linalg.norm(px[1] - px[0]) / eps)


def _tiles(half: int, tile: int, overlap: int) -> list[tuple[int, int]]:
    """Top-left offsets of square tiles covering [-half, half)^2 with the given overlap."""
    step = tile - overlap
    n = max(1, int(np.ceil((2 * half - overlap) / step)))
    starts = -half + np.arange(n) * step
    starts = np.minimum(starts, half - tile)
    return [(int(x), int(y)) for y in starts for x in starts]


def detect_floor_board(
    image: np.ndarray,
    model: OcamModel,
    R_SC: np.ndarray,
    board: BoardSpec,
    camera_height_mm: float = 1200.0,
) -> np.ndarray:
    """Inner corners of the floor board in fisheye pixels (N, 2), row by row, unordered
    between the half-turn orderings (see `order_corners`); see `_detect`."""
    return _detect(image, model, R_SC, board, camera_height_mm)[0]


def _detect(
    image: np.ndarray,
    model: OcamModel,
    R_SC: np.ndarray,
    board: BoardSpec,
    camera_height_mm: float = 1200.0,
) -> tuple[np.ndarray, float]:
    """Inner corners of the floor board in fisheye pixels (N, 2) and their 1-sigma (px).

    The floor is resampled into virtual top-down views (tiles of one big view whose squares
    are about 20 px for a floor `camera_height_mm` below), OpenCV's detector runs on each
    tile, and the corners are mapped to the fisheye image and refined there to sub-pixel.
    """
    gray = to_gray(image)
    density = _centre_density(model)
    # The view's focal length: squares of about 24 px at the nominal floor distance, but
    # never much finer than the fisheye itself resolves at the nadir.
    f = max(24.0 * camera_height_mm / board.square_mm, 0.5 * density)
    f = min(f, VIEW_MAGNIFICATION * density * 2.0)
    half = int(np.ceil(f * np.tan(np.radians(VIEW_HALF_ANGLE_DEG))))
    board_px = (max(board.cols, board.rows) + 3) * board.square_mm * f / camera_height_mm
    tile = int(min(2 * half, max(640, 2.2 * board_px)))
    overlap = int(min(tile - 1, 1.2 * board_px))
    views = [TopView(f, (-x0, -y0), (tile, tile)) for x0, y0 in _tiles(half, tile, overlap)]
    rendered: dict[int, np.ndarray | None] = {}  # None: a flat tile, nothing to detect

    def search(detector: Detector) -> np.ndarray | None:
        for i, view in enumerate(views):
            if i not in rendered:
                sub = view.render(gray, model, R_SC)
                rendered[i] = sub if float(np.std(sub)) >= 5.0 else None
            sub_or_none = rendered[i]
            if sub_or_none is None:
                continue
            try:
                corners_v = detect_corners(sub_or_none, board, detector=detector)
            except FeatureNotFoundError:
                continue
            return model.ray_to_pixel(view.rays_S(corners_v) @ R_SC)
        return None

    # Most tiles hold no board: the quick classic pass over all of them first, and the
    # sector-based detector (slower, surer on blurred squares) only if it found nothing.
    found = search("quick")
    if found is None:
        found = search("sb")
    if found is None:
        raise FeatureNotFoundError(
            f"floor board: no complete {board.cols}x{board.rows} checkerboard found on the floor "
            "(all inner corners must be visible: park the arm out of the camera's view of the "
            "board, check --board and the system calibration's camera rotation)"
        )
    return _refine(gray, found, model, R_SC, board)


def _square_wave(u: np.ndarray, square: float, sigma: float) -> np.ndarray:
    """A +-1 square wave of half-period `square` (edges at multiples of it), blurred by a
    Gaussian of `sigma` (same units): the profile of a checkerboard row seen through a lens."""
    k = np.floor(u / square + 0.5)
    edge_distance = u - k * square
    return np.where(k % 2 == 0, 1.0, -1.0) * erf(edge_distance / (np.sqrt(2.0) * sigma))


def _fit_board_model(
    view: np.ndarray, local: np.ndarray, board: BoardSpec
) -> tuple[np.ndarray, float]:
    """Corners (N, 2) of the board in a top-down view, from a fit of the whole pattern, and
    their 1-sigma (px of the view).

    The view is a perspective image of the floor, so the board's plane maps to it by a
    homography H. An ideal, Gaussian-blurred checkerboard a * q(H^-1(u, v)) + b is fitted to
    every pixel of the corner grid's area (H, contrast, offset and blur free); the corners are
    H of the grid. Using all the pixels of all the edges removes the bias a small corner window
    shows on resampled, anti-aliased squares (measured: registration error 0.68 -> 0.28 mm).
    """
    sq = board.square_mm
    obj = board.object_points()[:, :2]
    H0, _ = cv2.findHomography(obj, local)
    if H0 is None:
        raise FeatureNotFoundError("floor board: no homography from the detected corners")
    h, w = view.shape
    vv, uu = np.mgrid[0:h, 0:w]
    pix = np.stack([uu.ravel(), vv.ravel(), np.ones(h * w)], axis=1).astype(float)
    bc = pix @ np.linalg.inv(H0).T
    bc = bc[:, :2] / bc[:, 2:]
    inside = (
        (bc[:, 0] > -0.5 * sq)
        & (bc[:, 0] < (board.cols - 0.5) * sq)
        & (bc[:, 1] > -0.5 * sq)
        & (bc[:, 1] < (board.rows - 0.5) * sq)
    )
    P, level = pix[inside], view.astype(float).ravel()[inside]

    def residuals(x: np.ndarray) -> np.ndarray:
        H = np.append(x[:8], 1.0).reshape(3, 3)
        b = P @ np.linalg.inv(H).T
        b = b[:, :2] / b[:, 2:]
        pattern = _square_wave(b[:, 0], sq, x[10]) * _square_wave(b[:, 1], sq, x[10])
        return x[8] * pattern + x[9] - level

    amplitude = 0.5 * float(np.percentile(level, 95) - np.percentile(level, 5))
    best = None
    for sign in (1.0, -1.0):
        x0 = np.concatenate(
            [(H0 / H0[2, 2]).ravel()[:8], [sign * amplitude, float(np.median(level)), 0.05 * sq]]
        )
        sol = least_squares(residuals, x0, x_scale="jac")
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None

    def corners_of(x: np.ndarray) -> np.ndarray:
        g = np.c_[obj, np.ones(len(obj))] @ np.append(x[:8], 1.0).reshape(3, 3).T
        return (g[:, :2] / g[:, 2:]).ravel()

    # 1-sigma of the corners from the fit's covariance (pixel noise through H).
    dof = max(1, best.fun.size - best.x.size)
    try:
        cov = (2.0 * best.cost / dof) * np.linalg.inv(best.jac.T @ best.jac)
        steps = 1e-7 * np.maximum(1.0, np.abs(best.x[:8]))
        G = np.stack(
            [
                (corners_of(best.x + d * e) - corners_of(best.x - d * e)) / (2.0 * d)
                for d, e in zip(steps, np.eye(best.x.size)[:8], strict=True)
            ],
            axis=1,
        )
        sigma = float(np.sqrt(np.mean(np.diag(G @ cov[:8, :8] @ G.T))))
    except np.linalg.LinAlgError:
        sigma = float("nan")
    return corners_of(best.x).reshape(-1, 2), sigma


def _refine(
    gray: np.ndarray, corners: np.ndarray, model: OcamModel, R_SC: np.ndarray, board: BoardSpec
) -> tuple[np.ndarray, float]:
    """Sub-pixel corners: the whole pattern fitted in a top-down view around the board (where
    the board is a plane seen in perspective: no lens distortion), mapped to fisheye pixels."""
    f = FINE_MAGNIFICATION * _centre_density(model)
    rays = model.pixel_to_ray(corners) @ R_SC.T
    if np.any(rays[:, 2] > -0.05):
        raise FeatureNotFoundError("floor board: the board is at or above the horizon")
    uv = f * np.stack([rays[:, 0], -rays[:, 1]], axis=1) / -rays[:, 2:3]
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    size = int(np.ceil(1.4 * np.max(hi - lo))) + 16
    x0, y0 = (lo + hi) / 2.0 - size / 2.0
    view = TopView(f, (-x0, -y0), (size, size))
    sub = view.render(gray, model, R_SC)
    local = uv - [x0, y0]
    grid = local.reshape(board.rows, board.cols, 2)
    spacing = min(
        np.linalg.norm(np.diff(grid, axis=1), axis=2).min(),
        np.linalg.norm(np.diff(grid, axis=0), axis=2).min(),
    )
    refined, sigma = _fit_board_model(sub, local, board)
    # The detector's corners may have an outlier (a few px); the fitted grid must still agree
    # with most of them, or the fit slid to another square.
    moved = np.linalg.norm(refined - local, axis=1)
    if not np.all(np.isfinite(refined)) or np.median(moved) > 0.25 * spacing:
        raise FeatureNotFoundError("floor board: corner refinement diverged (blurred board?)")
    return model.ray_to_pixel(view.rays_S(refined) @ R_SC), sigma / FINE_MAGNIFICATION


# ---- ordering and pose --------------------------------------------------------------------


def _sample(gray: np.ndarray, uv: np.ndarray, radius: int) -> np.ndarray:
    """Mean grey level in a (2r+1)^2 window around each pixel (N, 2)."""
    k = 2 * radius + 1
    blur = cv2.blur(gray.astype(np.float32), (k, k))
    u = np.clip(np.round(uv[:, 0]).astype(int), 0, gray.shape[1] - 1)
    v = np.clip(np.round(uv[:, 1]).astype(int), 0, gray.shape[0] - 1)
    return blur[v, u]


def order_corners(
    image: np.ndarray, corners_px: np.ndarray, model: OcamModel, board: BoardSpec
) -> tuple[np.ndarray, np.ndarray, float]:
    """Corners in the board's own order (module docstring), with T_CB and the RMS (rad).

    Mirrored orderings are recognised by the pose (a board seen from its back), the half-turn
    by the colour of the outer squares next to the two candidate first corners.
    """
    if (board.cols + board.rows) % 2 == 0 or board.cols == board.rows:
        raise InputError(
            f"board {board.cols}x{board.rows}: use a board with cols + rows odd and cols != "
            "rows (e.g. 9x6); otherwise its first corner is ambiguous"
        )
    pts = board.object_points()
    grid = corners_px.reshape(board.rows, board.cols, 2)
    rays = model.pixel_to_ray(grid.reshape(-1, 2))
    T, rms = board_pose(rays, pts)
    if T[:3, 2] @ T[:3, 3] < 0:  # z towards the camera: the ordering is mirrored
        grid = grid[:, ::-1]
        rays = model.pixel_to_ray(grid.reshape(-1, 2))
        T, rms = board_pose(rays, pts)
    s = board.square_mm
    # Outer square next to corner 0 (black on the right ordering) and its white neighbour,
    # and the same two at the opposite corner (the other candidate's first corner).
    far = np.array([(board.cols - 1) * s, (board.rows - 1) * s])
    probes = np.array(
        [
            [-s / 2, -s / 2, 0.0],
            [s / 2, -s / 2, 0.0],
            [far[0] + s / 2, far[1] + s / 2, 0.0],
            [far[0] - s / 2, far[1] + s / 2, 0.0],
        ]
    )
    cam = probes @ T[:3, :3].T + T[:3, 3]
    px = model.ray_to_pixel(cam)
    spacing = np.linalg.norm(grid[0, 1] - grid[0, 0])
    level = _sample(to_gray(image), px, max(1, int(0.2 * spacing)))
    here = level[1] - level[0]  # positive when corner 0's outer square is the dark one
    there = level[3] - level[2]
    if abs(here - there) < 20.0:
        raise FeatureNotFoundError(
            "floor board: cannot tell the board's first corner (outer squares not visible "
            "or too little contrast)"
        )
    if there > here:
        grid = grid[::-1, ::-1]
        rays = model.pixel_to_ray(grid.reshape(-1, 2))
        T, rms = board_pose(rays, pts)
    return grid.reshape(-1, 2), T, rms


_R_LEVEL = np.diag([1.0, -1.0, -1.0])  # board frame with z down, x along X_S at yaw 0
_DOWN = np.array([0.0, 0.0, -1.0])


def _pose(x: np.ndarray, level: bool) -> np.ndarray:
    """Board pose in S from parameters: (t, yaw) when level, (rotation vector, t) otherwise."""
    T = np.eye(4)
    if level:
        T[:3, :3] = rot_z(x[3]) @ _R_LEVEL
        T[:3, 3] = x[:3]
    else:
        T[:3, :3] = Rotation.from_rotvec(x[:3]).as_matrix()
        T[:3, 3] = x[3:]
    return T


def _residuals(
    x: np.ndarray, rays_S: np.ndarray, pts: np.ndarray, level: bool, prior_w: float
) -> np.ndarray:
    """Corner rays vs predicted directions (sines of the angles), plus the tilt prior."""
    T = _pose(x, level)
    p = pts @ T[:3, :3].T + T[:3, 3]
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    r = np.cross(rays_S, p).ravel()
    if level or prior_w <= 0.0:
        return r
    return np.concatenate([r, prior_w * (T[:2, 2] - _DOWN[:2])])


def tilt_prior_from_std(std: dict[str, float], floor_deg: float = 0.05) -> float:
    """The board-tilt prior (deg) that matches a calibration's camera roll/pitch 1-sigma: an
    uncertain camera rotation lets the board's own plane decide, a sure one keeps it level."""
    roll = float(std.get("cam_roll_deg", 0.0) or 0.0)
    pitch = float(std.get("cam_pitch_deg", 0.0) or 0.0)
    return max(float(np.hypot(roll, pitch)), floor_deg)


@dataclass
class Registration:
    """The result of one registration: poses (4x4, mm), fit quality and 1-sigma figures."""

    T_SB: np.ndarray
    T_S_board: np.ndarray
    T_B_board: np.ndarray
    corners_px: np.ndarray = field(repr=False)
    rms_deg: float
    rms_px: float
    tilt_prior_deg: float | None
    free_tilt_deg: float
    board_extent_S: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    corner_sigma_px: float = 0.0
    std: dict[str, float] = field(default_factory=dict)

    @property
    def level(self) -> bool:
        return self.tilt_prior_deg == 0.0

    def record(self, model_name: str | None = None) -> dict[str, Any]:
        """The `robot_base` entry of system.json (keys shared with truth.json first)."""
        out: dict[str, Any] = pose_record(self.T_SB)
        if model_name:
            out["model"] = model_name
        out.update(
            {
                "method": "floor_board",
                "tilt_prior_deg": self.tilt_prior_deg,
                "board_pose_S": pose_record(self.T_S_board),
                "offset_T_B_board": pose_record(self.T_B_board),
                "rms_deg": round(self.rms_deg, 6),
                "rms_px": round(self.rms_px, 4),
                "corner_sigma_px": round(self.corner_sigma_px, 4),
                "free_tilt_deg": round(self.free_tilt_deg, 4),
                "board_extent_S_mm": [round(v, 2) for v in self.board_extent_S],
                "std": {k: round(v, 6) for k, v in self.std.items()},
            }
        )
        return out


def register_from_corners(
    image: np.ndarray,
    corners_px: np.ndarray,
    model: OcamModel,
    R_SC: np.ndarray,
    board: BoardSpec,
    T_B_board: np.ndarray,
    tilt_prior_deg: float | None = 0.0,
    corner_sigma_px: float | None = None,
) -> Registration:
    """T_SB from detected floor-board corners (any of the orderings `detect_floor_board` gives).

    `corner_sigma_px`: the corners' 1-sigma in fisheye pixels (never taken below
    CORNER_NOISE_FLOOR_PX); None estimates it from the pose fit's residuals.

    `tilt_prior_deg`: how far the board's normal may be from Z of S a priori (the floor is
    level, but S is only as level as the calibrated camera rotation). 0 fits position and yaw
    on a level floor; None fits the free 6-DOF pose; a value in between weighs the two (use
    the calibration's own roll/pitch 1-sigma, `tilt_prior_from_std`).
    """
    ordered, T_CB, rms = order_corners(image, corners_px, model, board)
    R_S = np.eye(4)
    R_S[:3, :3] = R_SC
    T_free = R_S @ T_CB
    free_tilt = float(np.degrees(np.arccos(np.clip(-T_free[2, 2], -1.0, 1.0))))
    pts = board.object_points()
    rays_S = model.pixel_to_ray(ordered) @ R_SC.T
    level = tilt_prior_deg == 0.0
    # Angular 1-sigma of one corner ray (a pixel near the axis spans 1/density rad).
    if corner_sigma_px is not None and np.isfinite(corner_sigma_px):
        noise = max(corner_sigma_px, CORNER_NOISE_FLOOR_PX) / _centre_density(model)
    else:
        noise = max(rms * np.sqrt(2.0 / 3.0), 1e-7)
    if level:
        if free_tilt > MAX_LEVEL_TILT_DEG:
            raise CalibrationError(
                f"floor board: tilted {free_tilt:.1f} deg from level in S (more than "
                f"{MAX_LEVEL_TILT_DEG} deg): the board is not flat on the floor or the camera "
                "rotation in system.json is wrong"
            )
        x0 = np.concatenate([T_free[:3, 3], [np.arctan2(T_free[1, 0], T_free[0, 0])]])
        prior_w = 0.0
    else:
        x0 = np.concatenate([Rotation.from_matrix(T_free[:3, :3]).as_rotvec(), T_free[:3, 3]])
        # Corner residuals are sines of angles with 1-sigma `noise`; the prior rows are scaled
        # so that their 1-sigma (the tilt prior) weighs the same.
        prior_w = 0.0 if tilt_prior_deg is None else noise / np.radians(tilt_prior_deg)
    sol = least_squares(_residuals, x0, args=(rays_S, pts, level, prior_w), method="lm")
    T_S_board = _pose(sol.x, level)
    n_par = sol.x.size
    n_corner = 3 * len(pts)
    fit = sol.fun[:n_corner]
    rms = float(np.sqrt(np.mean(fit**2) * 3 / 2))
    T_board_B = invert_pose(T_B_board)
    T_SB = T_S_board @ T_board_B
    # 1-sigma of the base position and yaw: the corner noise through the fit (covariance of
    # the weighted least squares), then through T_board_B by numeric derivatives.
    try:
        cov = noise**2 * np.linalg.inv(sol.jac.T @ sol.jac)
    except np.linalg.LinAlgError:
        cov = np.full((n_par, n_par), np.nan)

    def base(x: np.ndarray) -> np.ndarray:
        T = _pose(x, level) @ T_board_B
        return np.array([*T[:3, 3], np.arctan2(T[1, 0], T[0, 0])])

    h = 1e-6
    D = np.stack([(base(sol.x + h * e) - base(sol.x - h * e)) / (2 * h) for e in np.eye(n_par)], 1)
    cov_b = D @ cov @ D.T
    std = {
        "x_mm": float(np.sqrt(cov_b[0, 0])),
        "y_mm": float(np.sqrt(cov_b[1, 1])),
        "z_mm": float(np.sqrt(cov_b[2, 2])),
        "yaw_deg": float(np.degrees(np.sqrt(cov_b[3, 3]))),
    }
    # The board's area in S (inner corners grown by 1.5 squares: its outer squares and margin).
    sq = board.square_mm
    outline = np.array(
        [
            [x, y, 0.0]
            for x in (-1.5 * sq, (board.cols + 0.5) * sq)
            for y in (-1.5 * sq, (board.rows + 0.5) * sq)
        ]
    )
    pts_S = outline @ T_S_board[:3, :3].T + T_S_board[:3, 3]
    lo, hi = pts_S.min(axis=0), pts_S.max(axis=0)
    return Registration(
        T_SB=T_SB,
        T_S_board=T_S_board,
        T_B_board=np.asarray(T_B_board, float),
        corners_px=ordered,
        rms_deg=float(np.degrees(rms)),
        rms_px=float(rms * _centre_density(model)),
        tilt_prior_deg=tilt_prior_deg,
        free_tilt_deg=free_tilt,
        board_extent_S=(float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])),
        corner_sigma_px=float(noise * _centre_density(model)),
        std=std,
    )


def register_robot(
    image: np.ndarray,
    model: OcamModel,
    R_SC: np.ndarray,
    board: BoardSpec,
    T_B_board: np.ndarray,
    tilt_prior_deg: float | None = 0.0,
    camera_height_mm: float = 1200.0,
) -> Registration:
    """Detect the floor board in `image` and return the robot base pose T_SB (see module);
    `tilt_prior_deg` as in `register_from_corners`."""
    img = np.asarray(image)
    if img.ndim not in (2, 3) or img.dtype != np.uint8:
        raise InputError(f"image: expected an 8-bit image, got {img.dtype} {img.shape}")
    if (img.shape[1], img.shape[0]) != tuple(model.image_size):
        raise InputError(
            f"image is {img.shape[1]}x{img.shape[0]} but the camera model is for "
            f"{model.image_size[0]}x{model.image_size[1]}"
        )
    corners, sigma = _detect(img, model, R_SC, board, camera_height_mm)
    return register_from_corners(
        img, corners, model, R_SC, board, T_B_board, tilt_prior_deg, corner_sigma_px=sigma
    )


__all__ = [
    "Registration",
    "TopView",
    "detect_floor_board",
    "order_corners",
    "pose_error",
    "pose_from_offset",
    "pose_record",
    "register_from_corners",
    "register_robot",
    "tilt_prior_from_std",
]
