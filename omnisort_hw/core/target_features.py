"""Features of the calibration targets and the checkerboard baseline, from one fisheye image.

What is extracted (records in `features.py`, the contract with the calibration methods):

- Blue markers: adaptive colour segmentation (blue saturation `(b - min(r, g)) / (b + 8)` where
  blue dominates, threshold by Otsu between the image's own background level and its blue
  pixels), connected components filtered by size and shape, pieces of one marker split by a
  wall corner merged, and a sub-pixel centre weighted by each pixel's marker coverage
  (blueness between the local background and the marker's own level, so blur and vignetting
  do not shift it). It is the centroid of the marker's image, not the image of its centre: on
  a large, near marker the two differ by up to ~0.5 px (perspective).
- Two-sided target: a white far wall with a black/white border between the far markers means
  the image shows the three-sided target, which is an error rather than two walls silently
  extracted from it.
- Assignment by geometry, in the nominal system frame S (camera looking down, image up = +Y):
  rays with X < 0 belong to the left wall, X > 0 to the right one. On a side wall at X = const
  the coordinates (Y/|X|, Z/|X|) of its markers form a rectangle whatever the distance: the two
  with the smaller Y/|X| are "near", and of each pair the higher one (larger Z/|X|) is on the
  border.
- Border (and wall/floor line) of each wall: the great circle through its two markers predicts
  the curve; intensity profiles across it (three parallel lines averaged) give the strongest
  edge of the expected polarity (white on the floor side of the border, black above; white on
  the wall side of the floor line), located to sub-pixel by a Gaussian fit of the gradient
  peak; a RANSAC great-circle fit to those points re-predicts the curve and a second, narrow
  pass measures it again. Only between the markers (their blobs are left out) and on the wall.
  `floor_px` is the wall/floor line; it is optional (empty when not found), the rest is not.
- Laser: `laser_stripe_points` once for the image, then the points whose rays fall inside the
  wall's white face (the spherical quadrilateral bounded by the border, the floor line or the
  floor markers, and the great circles through each end's two markers), and of those the
  inliers of one great circle (the stripe on a flat wall is a straight 3D line).

Three-sided target: walls "left", "right" and "far". Two marker layouts are understood:
the published one (8 markers; the side walls' far markers stand at the corners with the far
wall, which has none of its own: its markers dict is empty and its face is bounded by those
corner markers) and the simulator's (12 markers, four on each wall; the far wall's are named
as the simulator names them: "near" is its left end (-X), "far" its right end).

Checkerboards: one full board is detected (on the whole image, else on each half of it), masked
out, and the second one detected the same way; the one further towards -X (larger azimuth in S)
is "left", the other "far". The laser points on each board are those inside the board's outline
(inner corners extended by most of a square), filtered to one great circle.

Every failure raises `FeatureNotFoundError` saying what was not found and where, and an image
whose size differs from the camera model's raises `InputError`; nothing is returned half-found.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import cv2
import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.checkerboard import detect_corners
from omnisort_hw.core.features import (
    MARKER_NAMES,
    BoardFeatures,
    BoardsFeatures,
    TargetFeatures,
    WallFeatures,
)
from omnisort_hw.core.laser_stripe import check_bgr, laser_stripe_points
from omnisort_hw.core.radiometry import SRGB, ToneCurve
from omnisort_hw.errors import FeatureNotFoundError, InputError

KINDS = ("two-sided", "three-sided")
SIDES = ("left", "right")

_EDGE_STEP_PX = 2.0  # spacing of the edge samples along a border
_EDGE_FINE_PX = 4  # half-width of the second, narrow search across the predicted curve
_EDGE_TOL_PX = 1.0  # great-circle inlier tolerance of edge points
_EDGE_MAX_RMS_PX = 0.5  # a border whose points scatter more is not one straight line
_EDGE_MIN_FRACTION = 0.5  # of the samples between the markers that must give an edge point
_LASER_TOL_PX = 1.5  # great-circle inlier tolerance of laser points
_LASER_MIN_POINTS = 8
_FACE_MARGIN_PX = 3.0  # laser points this close to a face's boundary are left out
_MAX_BLOBS = 400  # blue candidates examined at most (largest first)
_MIN_EDGE_CONTRAST = 4.0  # grey levels per pixel: below this no edge is claimed


@dataclass(frozen=True)
class Blob:
    """A blue marker candidate: sub-pixel centre (u, v), area in pixels, and contrast (its blue
    saturation above the surrounding background, grey levels)."""

    uv: np.ndarray
    area: float
    contrast: float = 0.0

    @property
    def radius(self) -> float:
        return float(np.sqrt(self.area / np.pi))


@dataclass(frozen=True)
class LineEdge:
    """Sub-pixel points of an edge along a straight 3D line, its great circle and its residual."""

    points: np.ndarray
    normal: np.ndarray
    rms_px: float


# ---- small geometry helpers ------------------------------------------------------------------


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


# ---- markers ---------------------------------------------------------------------------------


def _blueness(image: np.ndarray) -> np.ndarray:
    """Blue saturation: (b - min(r, g)) where blue is the strongest channel (else 0), over the
    blue level (b + 8), float32. The ratio separates saturated markers from the grey-blue
    floor whatever the lighting (it finds markers; their coverage is `_linear_blueness`)."""
    b, g, r = (c.astype(np.float32) for c in cv2.split(image))
    blue = np.where(b > np.maximum(r, g) + 8.0, b - np.minimum(r, g), 0.0)
    return blue / (b + 8.0)


def _linear_blueness(patch: np.ndarray, tone: ToneCurve) -> np.ndarray:
    """b - min(r, g) in linear light (>= 0): proportional to a marker's coverage of a pixel,
    which the encoded difference is not (the tone curve bends it)."""
    lin = tone.linearise(patch)
    return np.maximum(lin[..., 0] - np.minimum(lin[..., 1], lin[..., 2]), 0.0)


def find_blue_markers(image_bgr: np.ndarray, tone: ToneCurve = SRGB) -> list[Blob]:
    """Blue marker blobs of the image, with sub-pixel centres (see the module docstring);
    `tone` is the camera's tone curve (coverage is measured in linear light)."""
    img = check_bgr(image_bgr)
    h, w = img.shape[:2]
    ratio = _blueness(img)
    background = float(np.percentile(ratio[::4, ::4], 99))
    above = ratio[ratio > background]
    if above.size < 8:
        return []
    vals = np.clip(above * 255.0, 0, 255).astype(np.uint8).reshape(-1, 1)
    otsu, _ = cv2.threshold(vals, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    thr = max(otsu / 255.0, background + 0.08)
    mask = (ratio > thr).astype(np.uint8)
    n_lab, labels, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n_lab <= 1:
        return []
    scale = w * h / 1920.0**2
    a_min, a_max = max(6.0, 12.0 * scale), 0.002 * w * h
    # specks far below a marker's size are noise; the rest (at most a few hundred, largest
    # first) are candidates, and pieces of one marker (split by a wall corner) are merged
    keep = np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] >= 0.5 * a_min) + 1
    keep = keep[np.argsort(-stats[keep, cv2.CC_STAT_AREA])[:_MAX_BLOBS]]
    if keep.size == 0:
        return []
    stats, cents = stats[keep], cents[keep]
    area = stats[:, cv2.CC_STAT_AREA].astype(float)
    radius = np.sqrt(area / np.pi)
    dist = np.linalg.norm(cents[:, None] - cents[None, :], axis=2)
    near = dist < 1.2 * (radius[:, None] + radius[None, :]) + 2.0
    group = np.arange(area.size)
    for _ in range(area.size):
        new = np.min(np.where(near, group[None, :], area.size), axis=1)
        if np.array_equal(new, group):
            break
        group = new
    blobs: list[Blob] = []
    for gid in np.unique(group):
        members = np.flatnonzero(group == gid)
        labels_of = keep[members]
        x0 = int(stats[members, cv2.CC_STAT_LEFT].min())
        y0 = int(stats[members, cv2.CC_STAT_TOP].min())
        x1 = int((stats[members, cv2.CC_STAT_LEFT] + stats[members, cv2.CC_STAT_WIDTH]).max())
        y1 = int((stats[members, cv2.CC_STAT_TOP] + stats[members, cv2.CC_STAT_HEIGHT]).max())
        tot = float(stats[members, cv2.CC_STAT_AREA].sum())
        bw, bh = x1 - x0, y1 - y0
        if not a_min <= tot <= a_max or tot < 0.2 * bw * bh or max(bw, bh) > 6 * min(bw, bh):
            continue
        pad = 3
        xa, ya, xb, yb = max(x0 - pad, 0), max(y0 - pad, 0), min(x1 + pad, w), min(y1 + pad, h)
        own = np.isin(labels[ya:yb, xa:xb], labels_of).astype(np.uint8)
        zone = cv2.dilate(own, np.ones((2 * pad + 1, 2 * pad + 1), np.uint8)).astype(bool)
        ring = zone & ~cv2.dilate(own, np.ones((3, 3), np.uint8)).astype(bool)
        patch = _linear_blueness(img[ya:yb, xa:xb], tone)
        level = float(np.percentile(patch[own.astype(bool)], 80))
        base = max(float(np.median(patch[ring])) if ring.any() else 0.0, 0.0)
        if level <= base:
            continue
        wts = np.clip((patch - base) / (level - base), 0.0, 1.0) * zone
        yy, xx = np.mgrid[ya:yb, xa:xb]
        s = float(wts.sum())
        uv = np.array([(wts * xx).sum() / s, (wts * yy).sum() / s])
        blobs.append(Blob(uv, tot, level - base))
    return blobs


def _directions_S(blobs: list[Blob], model: OcamModel) -> np.ndarray:
    """Unit directions of the blobs in the nominal system frame."""
    return _nominal_S(model.pixel_to_ray(np.array([b.uv for b in blobs]).reshape(-1, 2)))


def _columns(S: np.ndarray, idx: np.ndarray) -> dict[str, int]:
    """Names for the four markers `idx` of one side wall from (Y/|X|, Z/|X|)."""
    along = S[idx, 1] / np.abs(S[idx, 0])
    order = idx[np.argsort(along)]
    near, far = order[:2], order[2:]
    names: dict[str, int] = {}
    for end, pair in (("near", near), ("far", far)):
        height = S[pair, 2] / np.abs(S[pair, 0])
        names[f"border_{end}"] = int(pair[int(np.argmax(height))])
        names[f"floor_{end}"] = int(pair[int(np.argmin(height))])
    return names


_RECTANGLE_CANDIDATES = 10


def _rectangle_cost(S: np.ndarray, quad: np.ndarray) -> float:
    """How far four marker directions are from a wall's marker rectangle: on the wall plane
    X = x_w, (Y/|X|, Z/|X|) are the plane's own coordinates scaled by 1/|x_w|; the two markers
    of each end share Y, the two of each height share Z (nearly so for a tilted camera)."""
    n = _columns(S, quad)
    a = {k: S[i, 1] / abs(S[i, 0]) for k, i in n.items()}
    h = {k: S[i, 2] / abs(S[i, 0]) for k, i in n.items()}
    span_a = abs(a["border_far"] + a["floor_far"] - a["border_near"] - a["floor_near"]) / 2
    span_h = abs(h["border_near"] + h["border_far"] - h["floor_near"] - h["floor_far"]) / 2
    if span_a < 1e-6 or span_h < 1e-6:
        return np.inf
    ends = abs(a["border_near"] - a["floor_near"]) + abs(a["border_far"] - a["floor_far"])
    levels = abs(h["border_near"] - h["border_far"]) + abs(h["floor_near"] - h["floor_far"])
    return float(ends / span_a + levels / span_h)


def _best_rectangle(S: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """The four candidates that best form a wall's marker rectangle."""
    quads = [np.array(q) for q in combinations(candidates.tolist(), 4)]
    return quads[int(np.argmin([_rectangle_cost(S, q) for q in quads]))]


def assign_markers(
    blobs: list[Blob], model: OcamModel, kind: str
) -> tuple[dict[str, dict[str, Blob]], list[Blob]]:
    """Markers per wall and name, from their geometry (see the module docstring).

    Returns ({wall: {name: blob}}, the blobs used); raises FeatureNotFoundError naming the wall
    whose markers are missing or too many.
    """
    expected = "8" if kind == "two-sided" else "8 or 12"
    if not blobs:
        raise FeatureNotFoundError(
            f"{kind} target: no blue markers found in the image (expected {expected}: 4 on "
            "each wall); is this the right target, and are the markers in view?"
        )
    S = _directions_S(blobs, model)
    sides = {"left": np.flatnonzero(S[:, 0] < 0), "right": np.flatnonzero(S[:, 0] >= 0)}
    allowed = (4,) if kind == "two-sided" else (4, 6)
    for side, idx in sides.items():
        if idx.size > max(allowed):
            # surplus: specks of JPEG chroma noise or blue clutter, pale next to the markers;
            # then, if still too many, the most marker-like (contrast x size) are kept, and for
            # the two-sided target the four of them that best form the markers' rectangle on
            # the wall plane (blue objects on the floor, a bin or a cube, do not)
            contrast = np.array([blobs[i].contrast for i in idx])
            idx = idx[contrast >= 0.3 * np.median(contrast)]
            score = np.array([blobs[i].contrast * np.sqrt(blobs[i].area) for i in idx])
            ranked = idx[np.argsort(-score)]
            if kind == "two-sided" and ranked.size > 4:
                sides[side] = np.sort(_best_rectangle(S, ranked[:_RECTANGLE_CANDIDATES]))
            else:
                sides[side] = np.sort(ranked[: max(allowed)])
    counts = {s: int(i.size) for s, i in sides.items()}
    bad = [s for s in SIDES if counts[s] not in allowed]
    if kind == "three-sided" and not bad and counts["left"] != counts["right"]:
        bad = [min(SIDES, key=lambda s: counts[s])]
    if bad:
        side = bad[0]
        where = (
            "at " + ", ".join(_fmt(blobs[i].uv) for i in sides[side])
            if sides[side].size
            else "none"
        )
        want = " or ".join(str(a) for a in allowed)
        raise FeatureNotFoundError(
            f"{side} wall: found {counts[side]} blue marker(s) where {want} were expected "
            f"({where}); {kind} target: {counts['left']} left, {counts['right']} right. "
            "Markers missing, covered, or not this target?"
        )
    walls: dict[str, dict[str, Blob]] = {}
    far: dict[str, Blob] = {}
    for side in SIDES:
        idx = sides[side]
        if idx.size == 4:
            names = _columns(S, idx)
        else:
            along = S[idx, 1] / np.abs(S[idx, 0])
            order = idx[np.argsort(along)]
            near, rest = order[:2], order[2:]
            h = S[rest, 2] / np.abs(S[rest, 0])
            top, low = rest[np.argsort(h)[2:]], rest[np.argsort(h)[:2]]
            a_top = S[top, 1] / np.abs(S[top, 0])
            a_low = S[low, 1] / np.abs(S[low, 0])
            side_far = np.array([top[np.argmin(a_top)], low[np.argmin(a_low)]])
            wall_far = np.array([top[np.argmax(a_top)], low[np.argmax(a_low)]])
            names = _columns(S, np.concatenate([near, side_far]))
            end = "near" if side == "left" else "far"
            far[f"border_{end}"], far[f"floor_{end}"] = blobs[wall_far[0]], blobs[wall_far[1]]
        walls[side] = {name: blobs[i] for name, i in names.items()}
    if kind == "three-sided":
        walls["far"] = far
    used = [b for wall in walls.values() for b in wall.values()]
    return walls, used


# ---- edges along great circles ---------------------------------------------------------------


def _gray(image: np.ndarray) -> np.ndarray:
    """Encoded grey levels (for face brightness checks, not for locating edges)."""
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY).astype(np.float32)


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


# ---- wall faces and laser --------------------------------------------------------------------


def _face_planes(
    model: OcamModel,
    border_a: Blob,
    border_b: Blob,
    floor_a: Blob,
    floor_b: Blob,
    border_normal: np.ndarray,
    floor_normal: np.ndarray | None,
) -> np.ndarray:
    """Inward unit normals (4, 3) of the great circles bounding a wall's white face: border,
    floor line (or the floor markers' circle), and the two ends (each end's two markers)."""
    ba, bb, fa, fb = model.pixel_to_ray(
        np.stack([b.uv for b in (border_a, border_b, floor_a, floor_b)])
    )
    centre = _unit(ba + bb + fa + fb)
    floor_n = floor_normal if floor_normal is not None else _unit(np.cross(fa, fb))
    planes = np.stack([border_normal, floor_n, _unit(np.cross(ba, fa)), _unit(np.cross(bb, fb))])
    return planes * np.where(planes @ centre < 0, -1.0, 1.0)[:, None]


def _laser_on_face(
    model: OcamModel,
    stripe: np.ndarray,
    stripe_rays: np.ndarray,
    planes: np.ndarray,
    what: str,
    corners: list[Blob],
) -> np.ndarray:
    """Stripe points inside the face, then the inliers of one great circle."""
    scale = pixel_scale(model, stripe_rays) if stripe.shape[0] else np.zeros(0)
    inside = np.all(
        stripe_rays @ planes.T > (_FACE_MARGIN_PX / np.maximum(scale, 1e-9))[:, None], axis=1
    )
    pts = stripe[inside]
    where = "the white face between the markers at " + ", ".join(_fmt(c.uv) for c in corners)
    if pts.shape[0] < _LASER_MIN_POINTS:
        raise FeatureNotFoundError(
            f"{what}: no laser stripe on {where} ({pts.shape[0]} stripe points there, at least "
            f"{_LASER_MIN_POINTS} needed); is the laser on and crossing the wall?"
        )
    _, inl, _ = fit_great_circle(model, pts, _LASER_TOL_PX)
    if inl.sum() < _LASER_MIN_POINTS:
        raise FeatureNotFoundError(
            f"{what}: the {pts.shape[0]} stripe points on {where} do not form one straight laser "
            f"line ({int(inl.sum())} on one great circle)"
        )
    return pts[inl]


def check_image(image_bgr: np.ndarray, model: OcamModel) -> np.ndarray:
    """The image as uint8 BGR, or InputError when it is not one or its size is not the model's."""
    img = check_bgr(image_bgr)
    size = (img.shape[1], img.shape[0])
    if size != tuple(model.image_size):
        raise InputError(
            f"image is {size[0]}x{size[1]} but the camera model is for "
            f"{model.image_size[0]}x{model.image_size[1]}: wrong camera, mode or model file"
        )
    return img


def _stripe(image: np.ndarray, model: OcamModel) -> tuple[np.ndarray, np.ndarray]:
    stripe = laser_stripe_points(image)
    if stripe.shape[0] == 0:
        raise FeatureNotFoundError(
            "no laser stripe anywhere in the image: is the laser on (and not too faint)?"
        )
    return stripe, model.pixel_to_ray(stripe)


def _wall(
    gray: np.ndarray,
    model: OcamModel,
    name: str,
    m: dict[str, Blob],
    ends: tuple[str, str],
    stripe: tuple[np.ndarray, np.ndarray],
    exclude: list[Blob],
) -> WallFeatures:
    """Border, floor line and laser of one wall whose markers are named m[border_/floor_ + end]."""
    e0, e1 = ends
    bn, bf, fn, ff = m[f"border_{e0}"], m[f"border_{e1}"], m[f"floor_{e0}"], m[f"floor_{e1}"]
    r_floor = model.pixel_to_ray(np.stack([fn.uv, ff.uv])).mean(axis=0)
    r_border = model.pixel_to_ray(np.stack([bn.uv, bf.uv])).mean(axis=0)
    border = find_line_edge(gray, model, bn, bf, r_floor, f"{name} wall border", exclude)
    try:
        floor: LineEdge | None = find_line_edge(
            gray, model, fn, ff, r_border, f"{name} wall/floor line", exclude, below_only=True
        )
    except FeatureNotFoundError:
        floor = None
    planes = _face_planes(
        model, bn, bf, fn, ff, border.normal, None if floor is None else floor.normal
    )
    laser = _laser_on_face(model, *stripe, planes, f"{name} wall", [bn, bf, ff, fn])
    markers = {k: v.uv.copy() for k, v in m.items() if k in MARKER_NAMES}
    return WallFeatures(
        border_px=border.points,
        laser_px=laser,
        markers_px=markers,
        floor_px=floor.points if floor is not None else np.zeros((0, 2)),
    )


def _face_level(
    gray: np.ndarray, model: OcamModel, m: dict[str, Blob], ends: tuple[str, str]
) -> float:
    """Median grey level inside the quadrilateral of a wall's four markers (its white face)."""
    e0, e1 = ends
    c = model.pixel_to_ray(
        np.stack(
            [m[f"floor_{e0}"].uv, m[f"floor_{e1}"].uv, m[f"border_{e0}"].uv, m[f"border_{e1}"].uv]
        )
    )
    s, t = np.meshgrid(np.linspace(0.25, 0.75, 7), np.linspace(0.2, 0.6, 5))
    s, t = s.ravel()[:, None], t.ravel()[:, None]
    rays = (1 - s) * (1 - t) * c[0] + s * (1 - t) * c[1] + (1 - s) * t * c[2] + s * t * c[3]
    uv = model.ray_to_pixel(_unit(rays)).astype(np.float32)
    vals = cv2.remap(
        gray, uv[:, 0:1], uv[:, 1:2], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
    )
    return float(np.median(vals))


def _check_far_end_open(
    gray: np.ndarray,
    model: OcamModel,
    walls_m: dict[str, dict[str, Blob]],
    corners: dict[str, Blob],
    used: list[Blob],
) -> None:
    """Two-sided target: no third wall may close the far end (a face as white as the side walls'
    below a black/white border from one far border marker to the other), else the image shows
    the three-sided target and a two-sided calibration would silently ignore its far wall."""
    white = min(_face_level(gray, model, walls_m[s], ("near", "far")) for s in SIDES)
    if _face_level(gray, model, corners, ("near", "far")) < 0.8 * white:
        return
    r_floor = model.pixel_to_ray(np.stack([corners["floor_near"].uv, corners["floor_far"].uv]))
    try:
        find_line_edge(
            gray,
            model,
            corners["border_near"],
            corners["border_far"],
            r_floor.mean(axis=0),
            "far wall border",
            used,
        )
    except FeatureNotFoundError:
        return
    raise FeatureNotFoundError(
        "two-sided target: a third white wall with a black/white border closes the far end "
        f"between the markers at {_fmt(corners['border_near'].uv)} and "
        f"{_fmt(corners['border_far'].uv)}; this looks like the three-sided target"
    )


def extract_target_features(
    image_bgr: np.ndarray, model: OcamModel, kind: str = "two-sided", tone: ToneCurve = SRGB
) -> TargetFeatures:
    """Markers, borders, wall/floor lines and laser points of every wall of the target.
    `tone`: the camera's tone curve; edges and marker coverage are measured in linear light."""
    if kind not in KINDS:
        raise InputError(f"target kind must be one of {', '.join(KINDS)}, got {kind!r}")
    image = check_image(image_bgr, model)
    walls_m, used = assign_markers(find_blue_markers(image, tone), model, kind)
    gray = _gray(image)
    light = tone.luminance(image)
    stripe = _stripe(image, model)
    walls: dict[str, WallFeatures] = {}
    for side in SIDES:
        walls[side] = _wall(light, model, side, walls_m[side], ("near", "far"), stripe, used)
    left, right = walls_m["left"], walls_m["right"]
    own = walls_m.get("far", {})
    corners = own or {
        "border_near": left["border_far"],
        "floor_near": left["floor_far"],
        "border_far": right["border_far"],
        "floor_far": right["floor_far"],
    }
    if kind == "two-sided":
        _check_far_end_open(gray, model, walls_m, corners, used)
    else:
        try:
            far = _wall(light, model, "far", corners, ("near", "far"), stripe, used)
        except FeatureNotFoundError as exc:
            raise FeatureNotFoundError(f"{exc} (is this the two-sided target?)") from None
        if not own:
            far.markers_px = {}
        walls["far"] = far
    return TargetFeatures(kind, (image.shape[1], image.shape[0]), walls)


# ---- checkerboards ---------------------------------------------------------------------------


def _board_outline(corners: np.ndarray, cols: int, rows: int, extend: float) -> np.ndarray:
    """Polygon (P, 2) around the board: its boundary corners pushed out by `extend` squares
    (each along the local grid direction, so it follows the fisheye's curvature)."""
    g = corners.reshape(rows, cols, 2)
    out = g.copy()
    out[0] += extend * (g[0] - g[1])
    out[-1] += extend * (g[-1] - g[-2])
    out[:, 0] += extend * (g[:, 0] - g[:, 1])
    out[:, -1] += extend * (g[:, -1] - g[:, -2])
    ring = np.concatenate([out[0, :], out[1:, -1], out[-1, -2::-1], out[-2:0:-1, 0]])
    return ring


def _board_mask(shape: tuple[int, int], outline: np.ndarray) -> np.ndarray:
    mask = np.zeros(shape, np.uint8)
    cv2.fillPoly(mask, [np.round(outline).astype(np.int32)], 1)
    return mask.astype(bool)


def _detect_board(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """One full board: on the whole image, else on each half with the rest greyed out (two
    boards side by side can confuse the detector's quad linking; alone, each is found)."""
    try:
        return detect_corners(image, size)
    except FeatureNotFoundError as exc:
        first_error = exc
    h, w = image.shape[:2]
    halves = (
        (slice(0, h // 2 + h // 8), slice(None)),
        (slice(None), slice(0, w // 2 + w // 8)),
        (slice(None), slice(w // 2 - w // 8, w)),
        (slice(h // 2 - h // 8, h), slice(None)),
    )
    for rows, cols in halves:
        part = np.full_like(image, 128)
        part[rows, cols] = image[rows, cols]
        try:
            return detect_corners(part, size)
        except FeatureNotFoundError:
            continue
    raise first_error


def extract_board_features(
    image_bgr: np.ndarray,
    model: OcamModel,
    inner_corners: tuple[int, int] = (9, 6),
    square_mm: float = 97.0,
) -> BoardsFeatures:
    """Corners of the two perpendicular boards ("left", "far") and the laser on each."""
    image = check_image(image_bgr, model)
    cols, rows = inner_corners
    h, w = image.shape[:2]
    try:
        first = _detect_board(image, (cols, rows))
    except FeatureNotFoundError as exc:
        raise FeatureNotFoundError(f"checkerboard target: {exc}") from None
    masked = image.copy()
    masked[_board_mask((h, w), _board_outline(first, cols, rows, 1.5))] = 128
    try:
        second = _detect_board(masked, (cols, rows))
    except FeatureNotFoundError:
        raise FeatureNotFoundError(
            f"checkerboard target: one {cols}x{rows} board found around "
            f"{_fmt(first.mean(axis=0))}, the second (perpendicular) board was not found"
        ) from None
    boards = [first, second]
    S = _nominal_S(model.pixel_to_ray(np.stack([b.mean(axis=0) for b in boards])))
    azimuth = np.arctan2(S[:, 1], S[:, 0])
    left_i = int(np.argmax(azimuth))
    stripe = laser_stripe_points(image)
    if stripe.shape[0] == 0:
        raise FeatureNotFoundError(
            "no laser stripe anywhere in the image: is the laser on (and not too faint)?"
        )
    out: dict[str, BoardFeatures] = {}
    for i, corners in enumerate(boards):
        name = "left" if i == left_i else "far"
        mask = _board_mask((h, w), _board_outline(corners, cols, rows, 0.8))
        ij = np.clip(np.round(stripe).astype(int), 0, [w - 1, h - 1])
        pts = stripe[mask[ij[:, 1], ij[:, 0]]]
        where = f"the {name} board around {_fmt(corners.mean(axis=0))}"
        if pts.shape[0] < _LASER_MIN_POINTS:
            raise FeatureNotFoundError(
                f"{name} board: no laser stripe on {where} ({pts.shape[0]} stripe points, at "
                f"least {_LASER_MIN_POINTS} needed); is the laser on and crossing the board?"
            )
        _, inl, _ = fit_great_circle(model, pts, _LASER_TOL_PX)
        if inl.sum() < _LASER_MIN_POINTS:
            raise FeatureNotFoundError(
                f"{name} board: the stripe points on {where} do not form one straight line"
            )
        out[name] = BoardFeatures(name, (cols, rows), float(square_mm), corners, pts[inl])
    return BoardsFeatures((w, h), {"left": out["left"], "far": out["far"]})


# ---- review ----------------------------------------------------------------------------------


def draw_target_features(
    image: np.ndarray, features: TargetFeatures | BoardsFeatures
) -> np.ndarray:
    """A copy of the image with the features drawn: markers (blue rings, labelled), border
    (yellow), wall/floor line (cyan), laser (green), board corners (magenta, first one ringed)."""
    out = image.copy() if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    thick = max(1, round(out.shape[1] / 1000))

    def dots(pts: np.ndarray, colour: tuple[int, int, int], r: int = 1) -> None:
        for u, v in np.round(np.asarray(pts, float).reshape(-1, 2)).astype(int):
            cv2.circle(out, (int(u), int(v)), r, colour, -1, cv2.LINE_AA)

    if isinstance(features, BoardsFeatures):
        for name, board in features.boards.items():
            dots(board.corners_px, (255, 0, 255), 2 * thick)
            c0 = np.round(board.corners_px[0]).astype(int)
            cv2.circle(out, (int(c0[0]), int(c0[1])), 6 * thick, (255, 0, 255), thick)
            dots(board.laser_px, (0, 255, 0), thick)
            cen = np.round(board.corners_px.mean(axis=0)).astype(int)
            cv2.putText(
                out,
                name,
                (int(cen[0]), int(cen[1])),
                cv2.FONT_HERSHEY_SIMPLEX,
                0.6 * thick,
                (255, 0, 255),
                thick,
                cv2.LINE_AA,
            )
        return out
    for wall_name, wall in features.walls.items():
        dots(wall.border_px, (0, 255, 255), thick)
        dots(wall.floor_px, (255, 255, 0), thick)
        dots(wall.laser_px, (0, 255, 0), thick)
        for name, uv in wall.markers_px.items():
            p = np.round(np.asarray(uv, float)).astype(int)
            cv2.circle(out, (int(p[0]), int(p[1])), 8 * thick, (255, 80, 0), thick, cv2.LINE_AA)
            cv2.putText(
                out,
                f"{wall_name[0].upper()}:{name}",
                (int(p[0]) + 10 * thick, int(p[1])),
                cv2.FONT_HERSHEY_SIMPLEX,
                0.45 * thick,
                (255, 80, 0),
                thick,
                cv2.LINE_AA,
            )
    return out
