"""Great circles of the fisheye camera, the geometry under the target's feature extraction.

A straight 3D line through the scene images as a great circle of rays (the plane through the
line and the projection centre), so borders, wall/floor lines and laser stripes on flat walls
are all fitted and sampled as great circles: a RANSAC fit to pixels, residuals in pixels (the
model's radial scale), and rays along an arc. Also the small helpers that marker assignment,
edge location and extraction share (the nominal system frame, pixel formatting for errors).
"""

from __future__ import annotations

import numpy as np

from omnisort_hw.core.camera_model import OcamModel


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _nominal_S(rays: np.ndarray) -> np.ndarray:
    """Rays of C in the nominal system frame (camera looking straight down, image up = +Y)."""
    return np.stack([rays[..., 0], -rays[..., 1], -rays[..., 2]], axis=-1)


def _fmt(uv: np.ndarray) -> str:
    return f"({uv[0]:.0f}, {uv[1]:.0f})"


def pixel_scale(model: OcamModel, rays: np.ndarray) -> np.ndarray:
    """Pixels per radian at each ray: d rho / d theta of the model (the radial scale)."""
    theta = model.angle_from_axis(rays)
    deriv = np.polynomial.polynomial.polyder(model.inv_poly)
    return np.abs(np.polynomial.polynomial.polyval(theta, deriv))


def great_circle_residuals_px(model: OcamModel, uv: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Pixel distance from each point to the projection of the great circle with `normal`:
    each ray is moved to its nearest point on the circle and projected back."""
    rays = model.pixel_to_ray(uv)
    foot = _unit(rays - (rays @ normal)[:, None] * normal[None, :])
    return np.linalg.norm(model.ray_to_pixel(foot) - uv, axis=1)


def fit_great_circle(
    model: OcamModel, uv: np.ndarray, tol_px: float, trials: int = 200
) -> tuple[np.ndarray, np.ndarray, float]:
    """Robust great circle through pixels: RANSAC on pairs, then SVD refits on the inliers.

    Returns (unit normal, inlier mask, RMS pixel residual of the inliers). Deterministic.
    """
    n = uv.shape[0]
    if n < 3:
        return np.array([0.0, 0.0, 1.0]), np.zeros(n, dtype=bool), np.inf
    rays = model.pixel_to_ray(uv)
    scale = pixel_scale(model, rays)
    rng = np.random.default_rng(0)
    i = rng.integers(0, n, trials)
    j = rng.integers(0, n, trials)
    cand = np.cross(rays[i], rays[j])
    norm = np.linalg.norm(cand, axis=1)
    cand = cand[norm > 1e-9] / norm[norm > 1e-9, None]
    if cand.shape[0] == 0:
        return np.array([0.0, 0.0, 1.0]), np.zeros(n, dtype=bool), np.inf
    res = np.abs(rays @ cand.T) * scale[:, None]
    best = cand[np.argmax((res < tol_px).sum(axis=0))]
    inl = np.abs(rays @ best) * scale < tol_px
    for _ in range(4):
        if inl.sum() < 3:
            break
        best = np.linalg.svd(rays[inl], full_matrices=False)[2][-1]
        new = np.abs(rays @ best) * scale < tol_px
        if np.array_equal(new, inl):
            break
        inl = new
    if inl.sum() < 3:
        return best, inl, np.inf
    rms = float(np.sqrt(np.mean(great_circle_residuals_px(model, uv[inl], best) ** 2)))
    return best, inl, rms


def _arc(a: np.ndarray, b: np.ndarray, normal: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Rays on the great circle with `normal`, from a's foot to b's foot, at fractions t."""
    a0 = _unit(a - (a @ normal) * normal)
    b0 = _unit(b - (b @ normal) * normal)
    omega = np.arctan2(np.linalg.norm(np.cross(a0, b0)), a0 @ b0)
    perp = _unit(np.cross(normal, a0))
    if perp @ b0 < 0:
        perp = -perp
    ang = omega * t
    return np.cos(ang)[:, None] * a0[None, :] + np.sin(ang)[:, None] * perp[None, :]
