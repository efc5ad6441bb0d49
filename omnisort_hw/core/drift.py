"""Calibration drift: has the camera turned on its mount since the cell was calibrated?

Two measurements, arrays in and out:

- `estimate_rotation`: the camera rotation between a reference image (the laser-off capture
  the robot was registered with, taken with the stored calibration) and a fresh capture. A
  rotation of a central camera about its viewpoint moves every pixel by a depth-independent
  warp (through the camera model), so every static edge in view (walls, borders, markers,
  bins, the floor board) measures it; moving things (arm, cubes) are outliers, down-weighted
  by a Huber loss. The fit is a coarse-to-fine Gauss-Newton on grey levels with a gain and an
  offset (exposure changes), and the covariance of the rotation comes from a delete-one-block
  jackknife over 64 image regions (16 sectors x 4 rings): it contains the pixel noise, its
  spatial correlation (blur, JPEG) and whatever the scene changes add, so the threshold needs
  no tuning per camera.
- `measure_board`: the floor board's inner corners, predicted from the stored calibration and
  T_SB (and the measured rotation), refined in the fresh capture; corners the arm hides fail a
  saddle test and are left out. It gives the pixel residuals against the stored prediction and
  the base shift a re-registration would make (T_SB from the visible corners with the stored
  camera rotation). Without a reference image it also gives the rotation on its own (fewer,
  closer features: a less precise fallback).

The decision (`decide`): drift when the rotation is significant, Hotelling's T^2 of the
jackknife (F distribution with 3 and K-3 degrees of freedom) above the quantile of the false
alarm rate, and larger than `min_angle_deg` (what the fit's own model cannot resolve).
Conventions: the camera now is R_SC_now = Rot(rotvec_S) . R_SC (rotation vector in S, rad).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation
from scipy.stats import chi2
from scipy.stats import f as f_dist

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.checkerboard import BoardSpec, to_gray
from omnisort_hw.core.frames import invert_pose
from omnisort_hw.core.records import BoardCheckReply, DecisionSummary
from omnisort_hw.errors import FeatureNotFoundError, InputError

FALSE_ALARM_RATE = 1e-6  # per check, for a camera that did not move
MIN_ANGLE_DEG = 0.02  # never call drift below this (0.45 mm at 1.3 m)
LEVELS = 3  # pyramid levels of the dense fit
MAX_SAMPLES = 60000  # grey-level samples per level
RIM_MARGIN_RAD = np.radians(4.0)  # the image circle's rim is fixed to the camera: keep off it
BLOCKS_ANGULAR, BLOCKS_RADIAL = 16, 4
MIN_BLOCK_SAMPLES = 100
NORM_SIGMA_PX, NORM_FLOOR = 8.0, 4.0  # local contrast normalisation (px, grey levels)


def rotation_in_S(R_SC: np.ndarray, rotvec_S: np.ndarray) -> np.ndarray:
    """R_SC of a camera turned by `rotvec_S` (rad, in S)."""
    return Rotation.from_rotvec(np.asarray(rotvec_S, float)).as_matrix() @ np.asarray(R_SC, float)


def _gray(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim not in (2, 3) or img.dtype != np.uint8:
        raise InputError(f"drift: expected an 8-bit image, got {img.dtype} {img.shape}")
    g = cv2.GaussianBlur(to_gray(img).astype(np.float32), (0, 0), 1.0)
    # Local contrast normalisation: vignetting, exposure, gamma and ambient light change grey
    # levels smoothly across the image; edges (what moves with a turn) stay.
    hp = g - cv2.GaussianBlur(g, (0, 0), NORM_SIGMA_PX)
    local = np.sqrt(cv2.GaussianBlur(hp * hp, (0, 0), NORM_SIGMA_PX))
    return hp / (local + NORM_FLOOR)


@dataclass
class RotationEstimate:
    """The camera's rotation since the reference, its jackknife covariance and fit figures."""

    rotvec_S: np.ndarray  # rad
    cov: np.ndarray  # 3x3, rad^2
    blocks: int
    samples: int
    inlier_fraction: float
    source: str  # "image" (dense, against the reference image) or "board" (corners only)

    @property
    def angle_deg(self) -> float:
        return float(np.degrees(np.linalg.norm(self.rotvec_S)))

    @property
    def std_deg(self) -> np.ndarray:
        return np.degrees(np.sqrt(np.clip(np.diag(self.cov), 0.0, None)))

    def statistic(self) -> tuple[float, float]:
        """(T^2, p-value that a camera that did not move gives a T^2 at least this big)."""
        try:
            t2 = float(self.rotvec_S @ np.linalg.solve(self.cov, self.rotvec_S))
        except np.linalg.LinAlgError:
            return float("inf"), 0.0
        k = self.blocks
        if self.source == "image" and k > 4:
            return t2, float(f_dist.sf((k - 3) / (3.0 * (k - 1)) * t2, 3, k - 3))
        return t2, float(chi2.sf(t2, 3))

    def threshold_deg(self, alpha: float = FALSE_ALARM_RATE) -> float:
        """The smallest angle (along the least precise direction) that would be called drift."""
        k = self.blocks
        if self.source == "image" and k > 4:
            t2 = f_dist.isf(alpha, 3, k - 3) * 3.0 * (k - 1) / (k - 3)
        else:
            t2 = chi2.isf(alpha, 3)
        sigma_max = float(np.sqrt(max(np.linalg.eigvalsh(self.cov).max(), 0.0)))
        return float(np.degrees(np.sqrt(t2) * sigma_max))


def _domain(model: OcamModel, shape: tuple[int, int], step: int) -> tuple[np.ndarray, np.ndarray]:
    """Full-resolution pixel positions of a level's grid inside the lens circle (off its rim)
    and their unit rays in C."""
    h, w = shape
    vv, uu = np.mgrid[0:h, 0:w]
    P = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(float) * step
    rays = model.pixel_to_ray(P)
    theta = np.arccos(np.clip(rays[:, 2] / np.linalg.norm(rays, axis=1), -1.0, 1.0))
    circle = min(model.theta_max, _circle_theta(model))
    ok = np.isfinite(theta) & (theta < circle - RIM_MARGIN_RAD)
    return np.flatnonzero(ok), rays[ok] / np.linalg.norm(rays[ok], axis=1, keepdims=True)


def _circle_theta(model: OcamModel) -> float:
    """The largest ray angle whose pixel lies inside the image."""
    w, h = model.image_size
    cu, cv = model.center_uv
    r = min(cu, cv, w - 1 - cu, h - 1 - cv)
    ray = model.pixel_to_ray(np.array([[cu + r, cv]]))[0]
    return float(np.arccos(ray[2] / np.linalg.norm(ray)))


def _warp(model: OcamModel, rays_C: np.ndarray, omega_C: np.ndarray, scale: float) -> np.ndarray:
    """Pixels (level units) of the reference rays seen by the turned camera."""
    R = Rotation.from_rotvec(-omega_C).as_matrix()
    return model.ray_to_pixel(rays_C @ R.T) / scale


def _sample(img: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear values of `img` at (N, 2) pixels, NaN outside (remap wants maps < 32767 wide)."""
    n = len(uv)
    m: np.ndarray = np.full((-(-n // 1024) * 1024, 2), -10.0, np.float32)
    m[:n] = uv
    m = m.reshape(-1, 1024, 2)
    out = cv2.remap(img, m[..., 0], m[..., 1], cv2.INTER_LINEAR, borderValue=np.nan)
    return out.ravel()[:n]


def _block_ids(P: np.ndarray, model: OcamModel) -> np.ndarray:
    d = P - np.asarray(model.center_uv)
    ang = (np.arctan2(d[:, 1], d[:, 0]) + np.pi) / (2 * np.pi) * BLOCKS_ANGULAR
    r = np.linalg.norm(d, axis=1)
    edges = np.percentile(r, np.linspace(0, 100, BLOCKS_RADIAL + 1)[1:-1])
    ring = np.searchsorted(edges, r)
    return np.minimum(ang.astype(int), BLOCKS_ANGULAR - 1) * BLOCKS_RADIAL + ring


def estimate_rotation(
    reference: np.ndarray,
    current: np.ndarray,
    model: OcamModel,
    R_SC: np.ndarray,
    mask: np.ndarray | None = None,
) -> RotationEstimate:
    """The camera rotation (in S) between `reference` and `current` (same size, 8-bit);
    `mask` (bool, image size) excludes pixels of the reference (e.g. the laser stripe)."""
    ref, cur = _gray(reference), _gray(current)
    if ref.shape != cur.shape:
        raise InputError(f"drift: reference image {ref.shape} and capture {cur.shape} differ")
    if (ref.shape[1], ref.shape[0]) != tuple(model.image_size):
        raise InputError(
            f"drift: image is {ref.shape[1]}x{ref.shape[0]} but the camera model is for "
            f"{model.image_size[0]}x{model.image_size[1]}"
        )
    R_SC = np.asarray(R_SC, float)
    refs, curs = [ref], [cur]
    for _ in range(LEVELS - 1):
        refs.append(cv2.pyrDown(refs[-1]))
        curs.append(cv2.pyrDown(curs[-1]))
    omega = np.zeros(3)  # rotation vector in C (rad)
    rng = np.random.default_rng(0)
    final: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float] | None = None
    for level in range(LEVELS - 1, -1, -1):
        scale = float(2**level)
        r_img, c_img = refs[level], curs[level]
        gx = cv2.Sobel(c_img, cv2.CV_32F, 1, 0, ksize=3) / 8.0
        gy = cv2.Sobel(c_img, cv2.CV_32F, 0, 1, ksize=3) / 8.0
        rgx = cv2.Sobel(r_img, cv2.CV_32F, 1, 0, ksize=3) / 8.0
        rgy = cv2.Sobel(r_img, cv2.CV_32F, 0, 1, ksize=3) / 8.0
        idx, rays = _domain(model, r_img.shape, int(scale))
        grad = np.hypot(rgx.ravel()[idx], rgy.ravel()[idx])
        keep = grad > np.percentile(grad, 75)
        if mask is not None:
            m = cv2.resize(mask.astype(np.uint8), (r_img.shape[1], r_img.shape[0]))
            keep &= m.ravel()[idx] == 0
        idx, rays = idx[keep], rays[keep]
        if idx.size > MAX_SAMPLES:
            pick = np.sort(rng.choice(idx.size, MAX_SAMPLES, replace=False))
            idx, rays = idx[pick], rays[pick]
        if idx.size < 50:
            raise FeatureNotFoundError("drift: the reference image has almost no edges to compare")
        ref_v = r_img.ravel()[idx].astype(float)
        gain = np.array([1.0, 0.0])
        for _ in range(12):
            uv = _warp(model, rays, omega, scale)
            cv_ = _sample(c_img, uv).astype(float)
            gu, gv = _sample(gx, uv).astype(float), _sample(gy, uv).astype(float)
            eps = 1e-5
            dW = [(_warp(model, rays, omega + eps * e, scale) - uv) / eps for e in np.eye(3)]
            J = np.stack(
                [gu * d[:, 0] + gv * d[:, 1] for d in dW] + [-ref_v, -np.ones_like(ref_v)], 1
            )
            r = cv_ - gain[0] * ref_v - gain[1]
            ok = np.isfinite(r) & np.all(np.isfinite(J), axis=1)
            rr = r[ok]
            s = 1.4826 * float(np.median(np.abs(rr - np.median(rr)))) + 1e-6
            k = 1.345 * s
            w = np.minimum(1.0, k / np.maximum(np.abs(rr), 1e-12))
            Jw = J[ok] * w[:, None]
            A = Jw.T @ J[ok]
            b = Jw.T @ rr
            try:
                step = -np.linalg.solve(A + 1e-9 * np.eye(5), b)
            except np.linalg.LinAlgError:
                break
            omega = omega + step[:3]
            gain = gain + step[3:]
            if np.linalg.norm(step[:3]) < 1e-8:
                break
        final = (J[ok], w, rr, rays_pixels(model, rays[ok]), k)
    # Delete-one-block jackknife at the solution (one Gauss-Newton step from it without block k).
    assert final is not None, "every level of the pyramid sets it"
    J, w, r, P, k = final
    blocks = _block_ids(P, model)
    Jw = J * w[:, None]
    A_all, b_all = Jw.T @ J, Jw.T @ r
    thetas = []
    for bid in np.unique(blocks):
        sel = blocks == bid
        if sel.sum() < MIN_BLOCK_SAMPLES:
            continue
        A_k = A_all - Jw[sel].T @ J[sel]
        b_k = b_all - Jw[sel].T @ r[sel]
        try:
            thetas.append(-np.linalg.solve(A_k + 1e-9 * np.eye(5), b_k)[:3])
        except np.linalg.LinAlgError:
            continue
    K = len(thetas)
    th = np.array(thetas)
    cov_C = (K - 1) / K * (th - th.mean(0)).T @ (th - th.mean(0)) if K > 3 else np.eye(3)
    # Rotation vector in C -> in S: Rot_S(w_S) R_SC = R_SC Rot_C(w_C)  =>  w_S = R_SC w_C.
    return RotationEstimate(
        rotvec_S=R_SC @ omega,
        cov=R_SC @ cov_C @ R_SC.T + 1e-18 * np.eye(3),
        blocks=K,
        samples=int(r.size),
        inlier_fraction=float(np.mean(np.abs(r) <= k)),
        source="image",
    )


def rays_pixels(model: OcamModel, rays_C: np.ndarray) -> np.ndarray:
    """Full-resolution pixels of rays in C."""
    return model.ray_to_pixel(rays_C)


# ---- the floor board -------------------------------------------------------------------------


def predict_board_corners(
    model: OcamModel, R_SC: np.ndarray, T_SB: np.ndarray, T_B_board: np.ndarray, board: BoardSpec
) -> np.ndarray:
    """Pixels (N, 2) of the board's inner corners (board order) through R_SC and T_SB."""
    T = np.asarray(T_SB, float) @ np.asarray(T_B_board, float)
    pts_S = board.object_points() @ T[:3, :3].T + T[:3, 3]
    return model.ray_to_pixel(pts_S @ np.asarray(R_SC, float))


def _saddle_ok(gray: np.ndarray, uv: np.ndarray, radius: float, min_contrast: float) -> np.ndarray:
    """Corners whose four quadrants alternate dark/light with contrast (a visible corner)."""
    off = 0.5 * radius
    quadrants = []
    for du, dv in ((-off, -off), (off, -off), (off, off), (-off, off)):
        quadrants.append(_sample(gray, uv + np.array([du, dv])))
    q = np.stack(quadrants, 1).astype(float)
    diag1, diag2 = q[:, 0] + q[:, 2], q[:, 1] + q[:, 3]
    contrast = np.abs(diag1 - diag2) / 2.0
    spread_in = np.maximum(np.abs(q[:, 0] - q[:, 2]), np.abs(q[:, 1] - q[:, 3]))
    return np.isfinite(contrast) & (contrast > min_contrast) & (spread_in < 0.5 * contrast)


@dataclass
class BoardCheck:
    """The floor board in the capture against the stored calibration's prediction."""

    predicted_px: np.ndarray = field(repr=False)
    measured_px: np.ndarray = field(repr=False)  # NaN where hidden
    visible: np.ndarray = field(repr=False)
    residual_px: np.ndarray = field(repr=False)  # measured - stored prediction (visible ones)
    base_shift_mm: float = float("nan")
    base_shift_xyz_mm: tuple[float, float, float] = (float("nan"),) * 3
    rotation: RotationEstimate | None = None

    @property
    def n_visible(self) -> int:
        return int(self.visible.sum())

    def summary(self) -> BoardCheckReply:
        res = np.linalg.norm(self.residual_px, axis=1) if self.residual_px.size else np.zeros(0)
        return BoardCheckReply(
            corners=int(self.visible.size),
            visible=self.n_visible,
            residual_px_median=round(float(np.median(res)), 3) if res.size else None,
            residual_px_max=round(float(res.max()), 3) if res.size else None,
            base_shift_mm=_r(self.base_shift_mm, 3),
            base_shift_xyz_mm=[_r(v, 3) for v in self.base_shift_xyz_mm],
        )


def _r(v: float, n: int) -> float | None:
    return round(float(v), n) if np.isfinite(v) else None


def measure_board(
    image: np.ndarray,
    model: OcamModel,
    R_SC: np.ndarray,
    T_SB: np.ndarray,
    T_B_board: np.ndarray,
    board: BoardSpec,
    rotvec_S: np.ndarray | None = None,
) -> BoardCheck:
    """Refine the board's corners where the calibration (turned by `rotvec_S`, when the
    rotation is known) predicts them; hidden corners fail the saddle test and are dropped."""
    gray = to_gray(np.asarray(image)).astype(np.float32)
    stored = predict_board_corners(model, R_SC, T_SB, T_B_board, board)
    R_now = R_SC if rotvec_S is None else rotation_in_S(R_SC, rotvec_S)
    start = predict_board_corners(model, R_now, T_SB, T_B_board, board)
    grid = stored.reshape(board.rows, board.cols, 2)
    spacing = float(
        min(
            np.linalg.norm(np.diff(grid, axis=1), axis=2).min(),
            np.linalg.norm(np.diff(grid, axis=0), axis=2).min(),
        )
    )
    win = max(2, int(0.35 * spacing))
    h, w = gray.shape
    inside = np.all((start > win + 2) & (start < [w - win - 3, h - win - 3]), axis=1)
    measured = np.full_like(start, np.nan)
    visible = np.zeros(len(start), bool)
    if inside.any():
        pts = start[inside].astype(np.float32).reshape(-1, 1, 2).copy()
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 0.001)
        refined = cv2.cornerSubPix(gray, pts, (win, win), (-1, -1), crit).reshape(-1, 2)
        moved = np.linalg.norm(refined - start[inside], axis=1)
        contrast = 0.1 * float(np.percentile(gray, 95) - np.percentile(gray, 5))
        ok = (moved < 0.25 * spacing) & _saddle_ok(gray, refined, 0.6 * spacing, contrast)
        ids = np.flatnonzero(inside)[ok]
        measured[ids] = refined[ok]
        visible[ids] = True
    out = BoardCheck(stored, measured, visible, measured[visible] - stored[visible])
    if out.n_visible >= 4:
        out.base_shift_xyz_mm, out.base_shift_mm = _base_shift(
            measured[visible], board.object_points()[visible], model, R_SC, T_SB, T_B_board
        )
    if out.n_visible >= 6:
        out.rotation = _board_rotation(measured[visible], stored[visible], model, R_SC)
    return out


def _base_shift(
    px: np.ndarray,
    pts: np.ndarray,
    model: OcamModel,
    R_SC: np.ndarray,
    T_SB: np.ndarray,
    T_B_board: np.ndarray,
) -> tuple[tuple[float, float, float], float]:
    """How far T_SB moves when the board pose is re-fitted to the visible corners with the
    stored camera rotation (what a re-registration would do)."""
    rays_S = model.pixel_to_ray(px) @ np.asarray(R_SC, float).T
    rays_S /= np.linalg.norm(rays_S, axis=1, keepdims=True)
    T0 = np.asarray(T_SB, float) @ np.asarray(T_B_board, float)

    def pose(x: np.ndarray) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = Rotation.from_rotvec(x[:3]).as_matrix() @ T0[:3, :3]
        T[:3, 3] = T0[:3, 3] + x[3:]
        return T

    def res(x: np.ndarray) -> np.ndarray:
        T = pose(x)
        p = pts @ T[:3, :3].T + T[:3, 3]
        p /= np.linalg.norm(p, axis=1, keepdims=True)
        return np.cross(rays_S, p).ravel()

    sol = least_squares(res, np.zeros(6), x_scale=np.r_[1e-3, 1e-3, 1e-3, 1.0, 1.0, 1.0])
    T_SB_new = pose(sol.x) @ invert_pose(T_B_board)
    d = T_SB_new[:3, 3] - np.asarray(T_SB, float)[:3, 3]
    return (float(d[0]), float(d[1]), float(d[2])), float(np.linalg.norm(d))


def _board_rotation(
    measured: np.ndarray, predicted: np.ndarray, model: OcamModel, R_SC: np.ndarray
) -> RotationEstimate:
    """The camera rotation from the board alone (no reference image): the turn that maps the
    predicted corner rays onto the measured ones; covariance from the residual scatter."""
    R_SC = np.asarray(R_SC, float)
    a = model.pixel_to_ray(predicted) @ R_SC.T
    b = model.pixel_to_ray(measured) @ R_SC.T
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)

    def res(x: np.ndarray) -> np.ndarray:
        # A direction fixed in S is seen along Rot(x)^T a by the turned camera, i.e. at b.
        return np.cross(a @ Rotation.from_rotvec(x).as_matrix(), b).ravel()

    sol = least_squares(res, np.zeros(3))
    dof = max(1, sol.fun.size - 3)
    sigma2 = float(sol.fun @ sol.fun) / dof * 1.5  # 2 of 3 cross-product rows carry noise
    try:
        cov = sigma2 * np.linalg.inv(sol.jac.T @ sol.jac)
    except np.linalg.LinAlgError:
        cov = np.full((3, 3), np.inf)
    n = len(measured)
    return RotationEstimate(sol.x, cov, n, n, 1.0, "board")


# ---- the decision ----------------------------------------------------------------------------


@dataclass
class DriftDecision:
    """The outcome of one check: drift or not, and why."""

    drift: bool
    angle_deg: float
    rotvec_deg: tuple[float, float, float]
    std_deg: tuple[float, float, float]
    threshold_deg: float
    t2: float
    p_value: float
    source: str

    def summary(self) -> DecisionSummary:
        return DecisionSummary(
            drift=self.drift,
            angle_deg=round(self.angle_deg, 4),
            rotvec_deg=[round(v, 4) for v in self.rotvec_deg],
            std_deg=[round(v, 5) for v in self.std_deg],
            threshold_deg=round(self.threshold_deg, 4),
            t2=round(min(self.t2, 1e12), 2),
            p_value=float(f"{self.p_value:.3g}"),
            source=self.source,
        )


def decide(
    est: RotationEstimate, alpha: float = FALSE_ALARM_RATE, min_angle_deg: float = MIN_ANGLE_DEG
) -> DriftDecision:
    """Drift when the rotation is significant at `alpha` and at least `min_angle_deg`."""
    t2, p = est.statistic()
    thr = max(est.threshold_deg(alpha), min_angle_deg)
    drift = bool(p < alpha and est.angle_deg >= min_angle_deg)
    rv = np.degrees(est.rotvec_S)
    sd = est.std_deg
    return DriftDecision(
        drift,
        est.angle_deg,
        (float(rv[0]), float(rv[1]), float(rv[2])),
        (float(sd[0]), float(sd[1]), float(sd[2])),
        thr,
        t2,
        p,
        est.source,
    )
