"""Intrinsic calibration of the OCamCalib model from checkerboard corners.

As OCamCalib does, and further:
1. linear estimate (Scaramuzza 2006): per image, the board pose's first two rotation columns
   and (t1, t2) from the cross-product constraint that does not involve the polynomial; then
   the polynomial and every t3 together in one linear least-squares system;
2. search of the distortion centre on shrinking grids, scored by the linear fit's residual;
3. ONE nonlinear least-squares refinement of everything together (centre, stretch,
   polynomial, all board poses) on pixel reprojection errors, with the Jacobian's sparsity
   given to the solver (each image's residuals depend on the intrinsics and its own pose);
   a robust first pass, rejection of outlier images, then a plain least-squares pass that
   gives the parameters' standard deviations.

Sensor coordinates here follow the camera frame C: with the stretch undone, a pixel offset
(du, dv) belongs to the ray (du, dv, g(rho)), g = -f (g > 0 near the centre).

Over 600 lines: one estimation in three stages that share the corner arrays, the parameter
layout and the image bookkeeping (rejections, per-image RMS); the report and the board-plane
refinement are modules of their own.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from omnisort_hw.core.board_views import (
    CornerRejection,
    Rejection,
    detect_views,
    min_corners,
)
from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.checkerboard import BoardSpec, to_gray
from omnisort_hw.core.choices import REFINEMENTS
from omnisort_hw.core.plane_refinement import refine_on_board_plane
from omnisort_hw.errors import CalibrationError

MIN_IMAGES = 3


@dataclass
class ImagePoints:
    """One image's corners and the matching board points (mm, Z = 0); `ids` are the corners'
    indices on the board, row by row (all of them unless some were dropped)."""

    name: str
    pixels: np.ndarray
    board: np.ndarray
    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, int))

    def __post_init__(self) -> None:
        if len(self.ids) != len(self.pixels):
            self.ids = np.arange(len(self.pixels))

    def without(self, drop: np.ndarray) -> ImagePoints:
        """The same image without the corners where `drop` (a boolean mask) is set."""
        keep = ~drop
        return ImagePoints(self.name, self.pixels[keep], self.board[keep], self.ids[keep])


@dataclass
class IntrinsicResult:
    """A calibrated model with its quality figures."""

    model: OcamModel
    rms_px: float
    per_image_rms_px: dict[str, float]
    images_used: list[str]
    images_rejected: list[Rejection]
    std: dict[str, Any]
    poses: dict[str, np.ndarray]  # name -> 4x4 board-to-camera transform (mm)
    residuals_px: dict[str, np.ndarray] = field(repr=False)
    degree: int = 0
    corners_rejected: list[CornerRejection] = field(default_factory=list)
    corners_px: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    corner_ids: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    refinement: dict[str, str] = field(default_factory=dict)
    corner_limit_px: float = 0.0
    # The refined parameter vector (intrinsics first, then 6 per pose: rotation vector, mm),
    # its covariance (sigma_px^2 (J^T J)^-1, poses included) and the radius scale of the
    # polynomial's coefficients: what core.intrinsics_uncertainty propagates.
    params: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    covariance: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    rho_scale: float = 0.0
    n_intrinsic: int = 0

    def record(self) -> dict[str, Any]:
        """The calibration's record for camera.json (besides the model itself)."""
        return {
            "rms_px": self.rms_px,
            "per_image_rms_px": self.per_image_rms_px,
            "images_used": self.images_used,
            "images_rejected": [{"file": r.name, "reason": r.reason} for r in self.images_rejected],
            "corners_rejected": [
                {"file": r.name, "corner": r.corner, "reason": r.reason}
                for r in self.corners_rejected
            ],
            "corner_refinement": self.refinement,
            "std": self.std,
            "poly_degree": self.degree,
        }


# ---- linear estimate -------------------------------------------------------------------


def _extrinsic_partial(du: np.ndarray, dv: np.ndarray, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """(r11, r12, r21, r22, t1, t2) up to scale from du*(r2.p + t2) - dv*(r1.p + t1) = 0."""
    M = np.stack([-dv * X, -dv * Y, du * X, du * Y, -dv, du], axis=1)
    _, _, vt = np.linalg.svd(M, full_matrices=False)
    return vt[-1]


def _complete_rotation(h: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Candidates (r1, r2 scaled to unit length, (t1, t2)) for the partial solution `h`."""
    r11, r12, r21, r22, t1, t2 = h
    a = r11 * r12 + r21 * r22
    b = r11**2 + r21**2
    c = r12**2 + r22**2
    # r31 r32 = -a and r31^2 - r32^2 = c - b
    x = 0.5 * ((c - b) + np.sqrt((c - b) ** 2 + 4 * a * a))
    r31 = np.sqrt(max(x, 0.0))
    r32 = -a / r31 if r31 > 1e-12 else np.sqrt(max(b - c, 0.0))
    out = []
    for s in (1.0, -1.0):
        r1 = np.array([r11, r21, s * r31])
        r2 = np.array([r12, r22, s * r32])
        lam = 1.0 / np.linalg.norm(r1)
        out.append((np.stack([r1 * lam, r2 * lam], axis=1), np.array([t1, t2]) * lam))
    return out


def _linear_solve(
    views: list[ImagePoints], centre: tuple[float, float], degree: int, rho_scale: float
) -> tuple[np.ndarray, list[np.ndarray], float]:
    """Scaramuzza's linear estimate at a given centre (no stretch).

    Returns g's coefficients in the scaled variable rho / rho_scale, the 4x4 poses, and the
    RMS angle (rad) between observed rays and the posed board points (the score of the centre).
    """
    parts = []
    for view in views:
        du = view.pixels[:, 0] - centre[0]
        dv = view.pixels[:, 1] - centre[1]
        X, Y = view.board[:, 0], view.board[:, 1]
        h = _extrinsic_partial(du, dv, X, Y)
        # Overall sign: the board lies on the side the rays point to (lambda > 0).
        if np.sum(du * (h[0] * X + h[1] * Y + h[4]) + dv * (h[2] * X + h[3] * Y + h[5])) < 0:
            h = -h
        parts.append((du, dv, X, Y, _complete_rotation(h)))
    powers = np.array([0, *range(2, degree + 1)])
    n_img = len(views)

    def system(choices: list[int]) -> tuple[np.ndarray, np.ndarray]:
        rows, rhs = [], []
        for k, (du, dv, X, Y, cands) in enumerate(parts):
            R2, t12 = cands[choices[k]]
            rho = np.sqrt(du * du + dv * dv) / rho_scale
            P = rho[:, None] ** powers[None, :]
            A = R2[1, 0] * X + R2[1, 1] * Y + t12[1]
            C = R2[0, 0] * X + R2[0, 1] * Y + t12[0]
            zr = R2[2, 0] * X + R2[2, 1] * Y
            block = np.zeros((2 * len(X), len(powers) + n_img))
            block[: len(X), : len(powers)] = A[:, None] * P
            block[len(X) :, : len(powers)] = C[:, None] * P
            block[: len(X), len(powers) + k] = -dv
            block[len(X) :, len(powers) + k] = -du
            rows.append(block)
            rhs.append(np.concatenate([dv * zr, du * zr]))
        return np.vstack(rows), np.concatenate(rhs)

    # Per image, keep the candidate that fits a low-degree polynomial better with g(0) > 0.
    choices = []
    for du, dv, X, Y, cands in parts:
        best, best_err = 0, np.inf
        for ci, (R2, t12) in enumerate(cands):
            rho = np.sqrt(du * du + dv * dv) / rho_scale
            A = R2[1, 0] * X + R2[1, 1] * Y + t12[1]
            C = R2[0, 0] * X + R2[0, 1] * Y + t12[0]
            zr = R2[2, 0] * X + R2[2, 1] * Y
            M = np.zeros((2 * len(X), 3))
            M[: len(X), 0], M[: len(X), 1], M[: len(X), 2] = A, A * rho**2, -dv
            M[len(X) :, 0], M[len(X) :, 1], M[len(X) :, 2] = C, C * rho**2, -du
            rhs = np.concatenate([dv * zr, du * zr])
            # Three unknowns: the normal equations are exact enough and far cheaper.
            sol = np.linalg.solve(M.T @ M, M.T @ rhs)
            err = float(np.linalg.norm(M @ sol - rhs))
            if sol[0] > 0 and err < best_err:
                best, best_err = ci, err
        choices.append(best)
    M, rhs = system(choices)
    sol = _least_squares_normal(M, rhs)
    coeffs = sol[: len(powers)]
    poses = []
    sq_err = []
    for k, (du, dv, X, Y, cands) in enumerate(parts):
        R2, t12 = cands[choices[k]]
        r3 = np.cross(R2[:, 0], R2[:, 1])
        T = np.eye(4)
        T[:3, 0], T[:3, 1], T[:3, 2] = R2[:, 0], R2[:, 1], r3
        T[:3, 3] = [t12[0], t12[1], sol[len(powers) + k]]
        poses.append(T)
        rho = np.sqrt(du * du + dv * dv) / rho_scale
        g = (rho[:, None] ** powers[None, :]) @ coeffs
        obs = np.stack([du, dv, g], axis=1)
        obs /= np.linalg.norm(obs, axis=1, keepdims=True)
        pts = (T[:3, :2] @ np.stack([X, Y])).T + T[:3, 3]
        pts /= np.linalg.norm(pts, axis=1, keepdims=True)
        sq_err.append(np.sum(np.cross(obs, pts) ** 2, axis=1))
    full = np.zeros(degree + 1)
    full[powers] = coeffs
    return full, poses, float(np.sqrt(np.mean(np.concatenate(sq_err))))


def _least_squares_normal(M: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Linear least squares through the column-scaled normal equations: a few unknowns and
    many rows, where LAPACK's lstsq spends most of its time on the tall matrix."""
    scale = np.linalg.norm(M, axis=0)
    scale[scale == 0] = 1.0
    Ms = M / scale
    return np.linalg.solve(Ms.T @ Ms, Ms.T @ rhs) / scale


def search_centre(
    views: list[ImagePoints], image_size: tuple[int, int], degree: int = 4
) -> tuple[float, float]:
    """Distortion centre by shrinking grid search of the linear estimate's ray residual."""
    w, h = image_size
    rho_scale = 0.5 * min(w, h)
    centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    span = 0.08 * min(w, h)
    for _ in range(4):
        offsets = np.linspace(-span, span, 5)
        best, best_score = centre, np.inf
        for ox in offsets:
            for oy in offsets:
                cand = centre + np.array([ox, oy])
                try:
                    _, _, score = _linear_solve(views, (cand[0], cand[1]), degree, rho_scale)
                except np.linalg.LinAlgError:
                    continue
                if score < best_score:
                    best, best_score = cand, score
        centre = best
        span /= 3.0
    return float(centre[0]), float(centre[1])


# ---- nonlinear refinement --------------------------------------------------------------


def _horner(coeffs: np.ndarray, x: np.ndarray) -> np.ndarray:
    out = np.full_like(x, coeffs[-1])
    for c in coeffs[-2::-1]:
        out = out * x + c
    return out


def _project(
    pts: np.ndarray,
    centre: np.ndarray,
    stretch: np.ndarray,
    g_scaled: np.ndarray,
    rho_scale: float,
    rho0: np.ndarray,
) -> np.ndarray:
    """Project camera-frame points by solving g(rho) r - rho z = 0 for rho (Newton, vectorised)."""
    r = np.sqrt(pts[:, 0] ** 2 + pts[:, 1] ** 2)
    z = pts[:, 2]
    dg = g_scaled[1:] * np.arange(1, len(g_scaled))
    s = rho0 / rho_scale
    for _ in range(6):
        h = _horner(g_scaled, s) * r - s * rho_scale * z
        dh = _horner(dg, s) * r - rho_scale * z
        s = s - h / np.where(np.abs(dh) > 1e-12, dh, 1e-12)
    rho = s * rho_scale
    scale = np.divide(rho, r, out=np.zeros_like(r), where=r > 1e-12)
    du, dv = pts[:, 0] * scale, pts[:, 1] * scale
    c, d, e = stretch
    # OCamCalib: (row, col) offsets = [[c, d], [e, 1]] (x_o, y_o) with x_o = dv, y_o = du.
    return np.stack([centre[0] + e * dv + du, centre[1] + c * dv + d * du], axis=1)


@dataclass
class _Problem:
    """All images' points stacked, so residuals are computed in one vectorised pass."""

    n_poly: int
    n_views: int
    board: np.ndarray  # (M, 3)
    pixels: np.ndarray  # (M, 2)
    view: np.ndarray  # (M,) image index of each point
    rho_scale: float
    rho0: np.ndarray  # (M,) Newton start radii

    @classmethod
    def build(
        cls, views: list[ImagePoints], degree: int, rho_scale: float, centre: np.ndarray
    ) -> _Problem:
        pixels = np.concatenate([v.pixels for v in views])
        return cls(
            n_poly=degree,
            n_views=len(views),
            board=np.concatenate([v.board for v in views]),
            pixels=pixels,
            view=np.concatenate([np.full(len(v.pixels), k) for k, v in enumerate(views)]),
            rho_scale=rho_scale,
            rho0=np.hypot(pixels[:, 0] - centre[0], pixels[:, 1] - centre[1]),
        )

    @property
    def n_intr(self) -> int:
        return 4 + self.n_poly  # cu, cv, c, d (= e), g coefficients (a1 = 0 left out)

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Parameters -> centre, stretch (c, d, e), scaled g coefficients, poses (n, 6).

        The stretch is kept symmetric (d = e): its rotational part is the same as turning every
        board pose about the optical axis, a gauge freedom that would leave it undetermined.
        """
        centre = x[0:2]
        stretch = np.array([x[2], x[3], x[3]])
        coeffs = x[4 : self.n_intr]
        poses = x[self.n_intr :].reshape(self.n_views, 6)
        return centre, stretch, coeffs, poses

    def residuals(self, x: np.ndarray) -> np.ndarray:
        centre, stretch, coeffs, poses = self.split(x)
        R = Rotation.from_rotvec(poses[:, :3]).as_matrix()[self.view]
        pts = np.einsum("nij,nj->ni", R, self.board) + poses[self.view, 3:]
        uv = _project(pts, centre, stretch, _g_full(coeffs), self.rho_scale, self.rho0)
        return (uv - self.pixels).ravel()

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """Forward differences exploiting the block structure: each image's residuals depend on
        the intrinsics and on its own pose only, so each of the 6 pose parameters is perturbed
        in all images at once (n_intr + 6 evaluations instead of n_intr + 6 n_views)."""
        f0 = self.residuals(x)
        J = np.zeros((f0.size, x.size))
        steps = 1e-7 * np.maximum(np.abs(x), 1.0)
        for i in range(self.n_intr):
            xp = x.copy()
            xp[i] += steps[i]
            J[:, i] = (self.residuals(xp) - f0) / steps[i]
        rows = np.repeat(self.view, 2)
        for j in range(6):
            cols = self.n_intr + 6 * np.arange(self.n_views) + j
            xp = x.copy()
            xp[cols] += steps[cols]
            diff = self.residuals(xp) - f0
            J[np.arange(f0.size), cols[rows]] = diff / steps[cols[rows]]
        return J

    def per_image_rms(self, res: np.ndarray) -> np.ndarray:
        sq = np.sum(res.reshape(-1, 2) ** 2, axis=1)
        return np.sqrt(np.bincount(self.view, sq, self.n_views) / np.bincount(self.view))


def _g_full(coeffs: np.ndarray) -> np.ndarray:
    """Scaled g coefficients with a1 = 0 inserted."""
    return np.concatenate([coeffs[:1], [0.0], coeffs[1:]])


def _refine(
    views: list[ImagePoints],
    centre: tuple[float, float],
    g_lin: np.ndarray,
    poses: list[np.ndarray],
    rho_scale: float,
) -> tuple[np.ndarray, _Problem, Any]:
    """Levenberg-Marquardt on all intrinsics and poses together."""
    degree = len(g_lin) - 1
    prob = _Problem.build(views, degree, rho_scale, np.array(centre))
    coeffs = np.concatenate([g_lin[:1], g_lin[2:]])
    pose_vec = [
        np.concatenate([Rotation.from_matrix(T[:3, :3]).as_rotvec(), T[:3, 3]]) for T in poses
    ]
    x0 = np.concatenate([np.array(centre), [1.0, 0.0], coeffs, *pose_vec])
    sol = least_squares(prob.residuals, x0, jac=prob.jacobian, method="lm", x_scale="jac")
    return sol.x, prob, sol


def _to_model(x: np.ndarray, prob: _Problem, size: tuple[int, int]) -> OcamModel:
    centre, stretch, coeffs, _ = prob.split(x)
    g = _g_full(coeffs) / prob.rho_scale ** np.arange(prob.n_poly + 1)
    return OcamModel.create(-g, (centre[0], centre[1]), (stretch[0], stretch[1], stretch[2]), size)


def _fit(
    views: list[ImagePoints],
    image_size: tuple[int, int],
    degrees: list[int],
    centre: tuple[float, float] | None = None,
) -> tuple[np.ndarray, _Problem, Any]:
    """Centre search (unless a start is given), linear estimate and refinement for each
    degree; the lowest degree whose RMS is within 1% of the best wins (more terms would fit
    the noise, not the lens)."""
    rho_scale = 0.5 * min(image_size)
    if centre is None:
        centre = search_centre(views, image_size)
    fits = []
    for deg in degrees:
        g_lin, poses, _ = _linear_solve(views, centre, deg, rho_scale)
        x, prob, sol = _refine(views, centre, g_lin, poses, rho_scale)
        fits.append((float(np.sqrt(np.mean(sol.fun**2))), x, prob, sol))
    best = min(f[0] for f in fits)
    _, x, prob, sol = next(f for f in fits if f[0] <= 1.01 * best)
    return x, prob, sol


def _refit(
    views: list[ImagePoints], names: list[str], x: np.ndarray, prob: _Problem
) -> tuple[np.ndarray, _Problem, Any]:
    """Levenberg-Marquardt again from a previous solution (same degree), on `views`: the
    images named `names` in the previous fit, some with fewer corners."""
    centre = x[:2]
    new = _Problem.build(views, prob.n_poly, prob.rho_scale, centre)
    poses = x[prob.n_intr :].reshape(prob.n_views, 6)
    index = {n: k for k, n in enumerate(names)}
    x0 = np.concatenate([x[: prob.n_intr], *(poses[index[v.name]] for v in views)])
    sol = least_squares(new.residuals, x0, jac=new.jacobian, method="lm", x_scale="jac")
    return sol.x, new, sol


def corner_limit_px(distances: np.ndarray) -> float:
    """Limit beyond which a corner's residual is a gross error, from the residuals themselves:
    Tukey's outer fence, Q3 + 3 IQR. It assumes no particular law (real residuals have
    heavier tails than Gaussian noise: blur, a board not quite flat), and it sits far
    enough out that it trims gross errors, not the tail of the honest corners."""
    q1, q3 = np.percentile(distances, [25.0, 75.0])
    return float(q3 + 3.0 * (q3 - q1))


def _neighbour_median(views: list[ImagePoints], prob: _Problem, res2: np.ndarray) -> np.ndarray:
    """Per corner, the median residual of its neighbours on the board (the corners one
    square away in the same image); a corner with no neighbour left gets zero."""
    out = np.zeros_like(res2)
    for k, view in enumerate(views):
        idx = np.flatnonzero(prob.view == k)
        b = view.board[:, :2]
        d = np.linalg.norm(b[:, None, :] - b[None, :, :], axis=2)
        step = np.min(d[d > 0]) if np.any(d > 0) else 1.0
        near = (d > 0) & (d < 1.5 * step)  # the 8 around it: one bad one cannot move the median
        r = res2[idx]
        for axis in (0, 1):
            vals = np.where(near, r[None, :, axis], np.nan)
            has = near.any(axis=1)
            out[idx[has], axis] = np.nanmedian(vals[has], axis=1)
    return out


def calibrate(
    views: list[ImagePoints],
    image_size: tuple[int, int],
    degree: int | None = None,
    rejected: list[Rejection] | None = None,
    corners_rejected: list[CornerRejection] | None = None,
    max_rounds: int = 6,
    centre: tuple[float, float] | None = None,
    outlier_factor: float = 3.0,
    outlier_floor_px: float = 1.0,
) -> IntrinsicResult:
    """Calibrate from detected corners, dropping single bad corners, not whole images.

    `degree=None` picks the polynomial degree (4..8). After each fit, every corner whose
    residual, both as it is and less the median of its board neighbours' residuals, exceeds
    `corner_limit_px` of the latter is dropped with its reason: a gross error of one corner
    stands out from its neighbours, a smooth trend (the lens model, a board not quite flat)
    does not and is left for the report to show. The fit is repeated from where it was (at
    most `max_rounds` times). An image is dropped only when fewer than `min_corners` of its
    corners remain, or when its RMS exceeds `outlier_factor` times the median (and
    `outlier_floor_px`): a whole board off together. At least MIN_IMAGES must remain.
    `centre` starts the fit there instead of searching the distortion centre.
    """
    rejected = list(rejected or [])
    corners_rejected = list(corners_rejected or [])
    views = list(views)
    if len(views) < MIN_IMAGES:
        raise CalibrationError(
            f"only {len(views)} usable image(s); at least {MIN_IMAGES} with a full board are needed"
        )
    n_board = max(int(v.ids.max()) + 1 for v in views)
    degrees = [degree] if degree else [4, 5, 6, 7, 8]
    x, prob, sol = _fit(views, image_size, degrees, centre)
    limit = 0.0
    dropped_any = False
    for _ in range(max_rounds):
        res2 = sol.fun.reshape(-1, 2)
        dist = np.linalg.norm(res2, axis=1)
        local = np.linalg.norm(res2 - _neighbour_median(views, prob, res2), axis=1)
        limit = corner_limit_px(local)
        # Worst first: a fit that still holds a gross error pulls other corners along (its
        # neighbours, boards at the rim), so a round drops only those at least half as far
        # off as the worst, and the next round judges the rest in a cleaner fit.
        drop_all = (dist > limit) & (local > limit) & (local >= 0.5 * local.max())
        # An image's RMS over the corners it keeps: one gross corner must not cost the image.
        kept_sq = np.where(drop_all, 0.0, dist**2)
        per_image = np.sqrt(
            np.bincount(prob.view, kept_sq, prob.n_views)
            / np.maximum(np.bincount(prob.view, ~drop_all, prob.n_views), 1)
        )
        image_limit = max(outlier_factor * float(np.median(per_image)), outlier_floor_px)
        if not drop_all.any() and not np.any(per_image > image_limit):
            break
        names = [v.name for v in views]
        kept = []
        for k, view in enumerate(views):
            d, loc, drop = dist[prob.view == k], local[prob.view == k], drop_all[prob.view == k]
            if len(view.ids) - drop.sum() < min_corners(n_board) or per_image[k] > image_limit:
                rejected.append(
                    Rejection(
                        view.name,
                        f"outlier image: RMS {per_image[k]:.2f} px (limit {image_limit:.2f} px),"
                        f" {int(drop.sum())} of {len(d)} corners beyond the corner limit",
                    )
                )
                continue
            corners_rejected += [
                CornerRejection(
                    view.name,
                    int(c),
                    f"residual {r:.2f} px, {q:.2f} px off its neighbours' (limit {limit:.2f} px)",
                )
                for c, r, q in zip(view.ids[drop], d[drop], loc[drop], strict=True)
            ]
            kept.append(view.without(drop))
        if len(kept) < MIN_IMAGES:
            raise CalibrationError(
                f"only {len(kept)} image(s) keep enough good corners; at least {MIN_IMAGES} needed"
            )
        views = kept
        if dropped_any or len(degrees) == 1:
            x, prob, sol = _refit(views, names, x, prob)
        else:  # the degree was chosen with the bad data in: choose it again without
            x, prob, sol = _fit(views, image_size, degrees, (float(x[0]), float(x[1])))
        dropped_any = True
    return _result(views, image_size, x, prob, sol, rejected, corners_rejected, limit)


def _result(
    views: list[ImagePoints],
    image_size: tuple[int, int],
    x: np.ndarray,
    prob: _Problem,
    sol: Any,
    rejected: list[Rejection],
    corners_rejected: list[CornerRejection],
    limit: float,
) -> IntrinsicResult:
    """The result record: model, residuals and the parameters' standard deviations."""
    res = sol.fun
    sigma2 = float(res @ res) / max(res.size - x.size, 1)
    J = prob.jacobian(x)
    cov = np.linalg.pinv(J.T @ J) * sigma2
    std_all = np.sqrt(np.clip(np.diag(cov), 0, None))
    std_g = std_all[4 : prob.n_intr] / prob.rho_scale ** np.array([0, *range(2, prob.n_poly + 1)])
    std = {
        "center_uv": [float(std_all[0]), float(std_all[1])],
        "stretch": {"c": float(std_all[2]), "d": float(std_all[3]), "e": float(std_all[3])},
        "poly": [float(std_g[0]), 0.0, *(float(v) for v in std_g[1:])],
        "sigma_px": float(np.sqrt(sigma2)),
    }
    per_image = prob.per_image_rms(res)
    _, _, _, pose_vec = prob.split(x)
    R = Rotation.from_rotvec(pose_vec[:, :3]).as_matrix()
    poses = {}
    for k, view in enumerate(views):
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R[k], pose_vec[k, 3:]
        poses[view.name] = T
    res2 = res.reshape(-1, 2)
    return IntrinsicResult(
        model=_to_model(x, prob, image_size),
        rms_px=float(np.sqrt(np.mean(np.sum(res2**2, axis=1)))),
        per_image_rms_px={v.name: float(r) for v, r in zip(views, per_image, strict=True)},
        images_used=[v.name for v in views],
        images_rejected=rejected,
        std=std,
        poses=poses,
        residuals_px={v.name: res2[prob.view == k] for k, v in enumerate(views)},
        degree=prob.n_poly,
        corners_rejected=corners_rejected,
        corners_px={v.name: v.pixels for v in views},
        corner_ids={v.name: v.ids for v in views},
        corner_limit_px=limit,
        params=x.copy(),
        covariance=cov,
        rho_scale=prob.rho_scale,
        n_intrinsic=prob.n_intr,
    )


# ---- images -> model -------------------------------------------------------------------


def calibrate_images(
    images: list[tuple[str, np.ndarray]],
    board: BoardSpec,
    degree: int | None = None,
    on_detected: Any = None,
    log: Any = None,
    refinement: str = "auto",
    max_rounds: int = 6,
) -> IntrinsicResult:
    """Detect, calibrate, re-measure every board on its plane, choose, calibrate again.

    `images` are (name, grayscale or BGR image) of one camera; an image whose full board is
    not found is rejected with the reason, a corner that is not at an intensity saddle is
    left out with its reason. `refinement` is "saddle" (sub-pixel saddle points only),
    "plane" (every board re-measured on its plane) or "auto": per image, the corners that
    agree better with the first model (pose fitted alone, model held) are kept.
    `max_rounds` bounds the rounds of dropping corners with gross residuals (0: none).
    `on_detected(name)` is called as each detection finishes (for a progress bar); `log` is a
    RunLog (or None).
    """
    if refinement not in REFINEMENTS:
        raise ValueError(f"refinement must be one of {REFINEMENTS}, got {refinement!r}")
    if not images:
        raise CalibrationError("no images given")
    size = (images[0][1].shape[1], images[0][1].shape[0])
    for name, img in images:
        if (img.shape[1], img.shape[0]) != size:
            raise CalibrationError(
                f"{name}: image is {img.shape[1]}x{img.shape[0]}, the first one is "
                f"{size[0]}x{size[1]}; all images must come from the same camera mode"
            )
    grays = {name: to_gray(img) for name, img in images}
    found, rejected, at_detection = detect_views(grays, board, MIN_IMAGES, on_detected)
    obj = board.object_points()
    saddle = {n: ImagePoints(n, d.corners, obj).without(~d.good) for n, d in found.items()}
    first = calibrate(
        list(saddle.values()), size, degree, rejected, at_detection, max_rounds=max_rounds
    )
    chosen: dict[str, ImagePoints] = {}
    methods: dict[str, str] = {}
    for name in first.images_used:
        plane_px = refine_on_board_plane(grays[name], board, first.model, first.poses[name])
        plane = ImagePoints(name, plane_px, obj).without(~found[name].good)
        pick = refinement
        if refinement == "auto":
            rms = {
                m: pose_only_rms(first.model, v, first.poses[name])
                for m, v in (("saddle", saddle[name]), ("plane", plane))
            }
            pick = min(rms, key=rms.__getitem__)
        chosen[name] = plane if pick == "plane" else saddle[name]
        methods[name] = pick
    dropped_first = [r for r in first.images_rejected if r.name in found]
    result = calibrate(
        list(chosen.values()),
        size,
        degree,
        rejected + dropped_first,
        at_detection,
        max_rounds=max_rounds,
        centre=first.model.center_uv,
    )
    result.refinement = {n: methods[n] for n in result.images_used}
    if log is not None:
        _log_result(log, result, grays)
    return result


def pose_only_rms(model: OcamModel, view: ImagePoints, pose: np.ndarray) -> float:
    """RMS reprojection distance of one image with the model held and only its pose fitted."""
    x0 = np.concatenate([Rotation.from_matrix(pose[:3, :3]).as_rotvec(), pose[:3, 3]])

    def residuals(x: np.ndarray) -> np.ndarray:
        pts = Rotation.from_rotvec(x[:3]).apply(view.board) + x[3:]
        return (model.ray_to_pixel(pts) - view.pixels).ravel()

    sol = least_squares(residuals, x0, method="lm", x_scale="jac")
    return float(np.sqrt(np.mean(np.sum(sol.fun.reshape(-1, 2) ** 2, axis=1))))


def _log_result(log: Any, result: IntrinsicResult, grays: dict[str, np.ndarray]) -> None:
    """Per image: the image, used corners, reprojected corners and residual figures."""
    for step, name in enumerate(result.images_used):
        corners = result.corners_px[name]
        log.set_step("image", step)
        log.image("intrinsics/image", grays[name])
        log.points2d("intrinsics/image/detected", corners, color=(0, 200, 0), radius=4.0)
        reproj = corners + result.residuals_px[name]
        log.points2d("intrinsics/image/reprojected", reproj, color=(255, 0, 0), radius=2.0)
        log.scalar("intrinsics/rms_px_per_image", result.per_image_rms_px[name])
    log.text(
        "intrinsics/result", json.dumps({"rms_px": result.rms_px, **result.record()}, indent=2)
    )
