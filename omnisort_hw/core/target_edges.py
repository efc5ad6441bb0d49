"""Straight edges of the calibration targets, located to sub-pixel along great circles.

Border (and wall/floor line) of each wall: the great circle through its two markers predicts
the curve; intensity profiles across it (three parallel lines averaged) give the strongest
edge of the expected polarity (white on the floor side of the border, black above; white on
the wall side of the floor line), located to sub-pixel by a Gaussian fit of the gradient
peak; a RANSAC great-circle fit to those points re-predicts the curve and a second, narrow
pass measures it again. Only between the markers (their blobs are left out) and on the wall.

Separate from `target_features.py` because edge location is one self-contained measurement
(markers in, points on one great circle out) that extraction calls once per border or line.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.great_circles import _arc, _fmt, _unit, fit_great_circle
from omnisort_hw.core.target_markers import Blob
from omnisort_hw.errors import FeatureNotFoundError

_EDGE_STEP_PX = 2.0  # spacing of the edge samples along a border
_EDGE_FINE_PX = 4  # half-width of the second, narrow search across the predicted curve
_EDGE_TOL_PX = 1.0  # great-circle inlier tolerance of edge points
_EDGE_MAX_RMS_PX = 0.5  # a border whose points scatter more is not one straight line
_EDGE_MIN_FRACTION = 0.5  # of the samples between the markers that must give an edge point
_MIN_EDGE_CONTRAST = 4.0  # grey levels per pixel: below this no edge is claimed


@dataclass(frozen=True)
class LineEdge:
    """Sub-pixel points of an edge along a straight 3D line, its great circle and its residual."""

    points: np.ndarray
    normal: np.ndarray
    rms_px: float


def _edge_scan(
    gray: np.ndarray,
    model: OcamModel,
    normal: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    offsets: np.ndarray,
    exclude: list[Blob],
    step_px: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Edge points across the projected great circle (normal towards the bright side) between
    rays a and b: for each sample, the gradient maximum of the profile along the image normal,
    to sub-pixel. Returns (points (K, 2), contrast (K,)); contrast <= 0 where none."""
    h, w = gray.shape
    ends = model.ray_to_pixel(np.stack([a, b]))
    count = int(np.clip(3.0 * np.linalg.norm(ends[1] - ends[0]) / step_px, 8, 4000))
    rays = _arc(a, b, normal, np.linspace(0.0, 1.0, count))
    px = model.ray_to_pixel(rays)
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(px, axis=0), axis=1))])
    marks = np.arange(0.0, length[-1], step_px)
    keep = np.unique(np.searchsorted(length, marks).clip(0, count - 1))
    rays, px = rays[keep], px[keep]
    tangent = _unit(np.gradient(px, axis=0))
    nrm = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    towards = model.ray_to_pixel(_unit(rays + 1e-3 * normal[None, :])) - px
    nrm *= np.where((towards * nrm).sum(axis=1) < 0, -1.0, 1.0)[:, None]
    ok = np.ones(px.shape[0], dtype=bool)
    for blob in exclude:
        ok &= np.linalg.norm(px - blob.uv, axis=1) > 1.6 * blob.radius + 4.0
    reach = float(np.abs(offsets).max()) + 3.0
    ok &= (px[:, 0] > reach) & (px[:, 0] < w - 1 - reach)
    ok &= (px[:, 1] > reach) & (px[:, 1] < h - 1 - reach)
    lines = np.array([-1.0, 0.0, 1.0])
    grid = (
        px[:, None, None, :]
        + offsets[None, None, :, None] * nrm[:, None, None, :]
        + lines[None, :, None, None] * tangent[:, None, None, :]
    ).astype(np.float32)
    k, nl, ns = grid.shape[:3]
    samples = cv2.remap(
        gray,
        grid[..., 0].reshape(k * nl, ns),
        grid[..., 1].reshape(k * nl, ns),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    ).reshape(k, nl, ns)
    prof = samples.mean(axis=1)
    grad = 0.5 * (prof[:, 2:] - prof[:, :-2])
    j = np.argmax(grad[:, 1:-1], axis=1) + 1
    r = np.arange(k)
    gm, g0, gp = grad[r, j - 1], grad[r, j], grad[r, j + 1]
    eps = 1e-3
    with np.errstate(divide="ignore", invalid="ignore"):
        lm, l0, lp = (np.log(np.maximum(x, eps)) for x in (gm, g0, gp))
        den_g = lm - 2.0 * l0 + lp
        delta = np.where(den_g < 0, 0.5 * (lm - lp) / den_g, 0.0)
        den_p = gm - 2.0 * g0 + gp
        delta_p = np.where(den_p < 0, 0.5 * (gm - gp) / den_p, 0.0)
    use_gauss = (gm > 0) & (gp > 0) & np.isfinite(delta)
    delta = np.clip(np.where(use_gauss, delta, delta_p), -0.5, 0.5)
    step = offsets[1] - offsets[0]
    offset = offsets[1 + j] + delta * step
    points = px + offset[:, None] * nrm
    contrast = np.where(ok, g0 / step, 0.0)
    return points, contrast


def find_line_edge(
    gray: np.ndarray,
    model: OcamModel,
    a: Blob,
    b: Blob,
    bright: np.ndarray,
    what: str,
    exclude: list[Blob],
    below_only: bool = False,
) -> LineEdge:
    """The edge along the straight 3D line near markers a and b, bright on the side of ray
    `bright`; `below_only`: it lies on the dark side of the markers' own great circle (the wall/
    floor line below the floor markers). Raises FeatureNotFoundError saying what and where."""
    ra, rb = model.pixel_to_ray(np.stack([a.uv, b.uv]))
    normal = _unit(np.cross(ra, rb))
    if normal @ bright < 0:
        normal = -normal
    where = f"between the markers at {_fmt(a.uv)} and {_fmt(b.uv)}"
    span = float(np.linalg.norm(a.uv - b.uv))
    reach = max(10.0, 0.15 * span)
    lo, hi = (-reach, 3.0) if below_only else (-reach, reach)
    offsets = np.arange(np.floor(lo), np.ceil(hi) + 1.0)
    pts, contrast = _edge_scan(gray, model, normal, ra, rb, offsets, exclude, _EDGE_STEP_PX)
    valid = contrast > 0
    if valid.sum() < 5:
        raise FeatureNotFoundError(f"{what}: no part of it in view {where}")
    level = float(np.median(contrast[valid]))
    good = valid & (contrast > 0.4 * level)
    if level < _MIN_EDGE_CONTRAST or good.sum() < 5:
        raise FeatureNotFoundError(
            f"{what}: no edge of the expected polarity found {where} (contrast {level:.1f} grey "
            "levels/px)"
        )
    n1, inl, _ = fit_great_circle(model, pts[good], 2.0 * _EDGE_TOL_PX)
    if inl.sum() < 5:
        raise FeatureNotFoundError(f"{what}: edge points {where} do not follow one straight line")
    if n1 @ normal < 0:
        n1 = -n1
    fine = np.arange(-_EDGE_FINE_PX, _EDGE_FINE_PX + 1.0)
    pts, contrast = _edge_scan(gray, model, n1, ra, rb, fine, exclude, _EDGE_STEP_PX)
    valid = contrast > 0
    good = valid & (contrast > 0.4 * np.median(contrast[valid])) if valid.any() else valid
    n2, inl, rms = fit_great_circle(model, pts[good], _EDGE_TOL_PX)
    if n2 @ n1 < 0:
        n2 = -n2
    found = int(inl.sum())
    if found < max(5, _EDGE_MIN_FRACTION * valid.sum()) or rms > _EDGE_MAX_RMS_PX:
        raise FeatureNotFoundError(
            f"{what}: only {found} of {int(valid.sum())} samples {where} lie on one straight "
            f"edge (RMS {rms:.2f} px); is it covered, bent or out of focus?"
        )
    return LineEdge(pts[good][inl], n2, rms)
