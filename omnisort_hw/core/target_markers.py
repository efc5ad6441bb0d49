"""Blue markers of the calibration targets: where they are in the image and which is which.

- Detection: adaptive colour segmentation (blue saturation `(b - min(r, g)) / (b + 8)` where
  blue dominates, threshold by Otsu between the image's own background level and its blue
  pixels), connected components filtered by size and shape, pieces of one marker split by a
  wall corner merged, and a sub-pixel centre weighted by each pixel's marker coverage
  (blueness between the local background and the marker's own level, so blur and vignetting
  do not shift it). It is the centroid of the marker's image, not the image of its centre: on
  a large, near marker the two differ by up to ~0.5 px (perspective).
- Assignment by geometry, in the nominal system frame S (camera looking down, image up = +Y):
  rays with X < 0 belong to the left wall, X > 0 to the right one. On a side wall at X = const
  the coordinates (Y/|X|, Z/|X|) of its markers form a rectangle whatever the distance: the two
  with the smaller Y/|X| are "near", and of each pair the higher one (larger Z/|X|) is on the
  border.

Separate from `target_features.py` because the markers are found and named from colour and
geometry alone, before any edge or laser is looked for.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import cv2
import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.great_circles import _fmt, _nominal_S
from omnisort_hw.core.laser_stripe import check_bgr
from omnisort_hw.core.radiometry import SRGB, ToneCurve
from omnisort_hw.errors import FeatureNotFoundError

SIDES = ("left", "right")

_MAX_BLOBS = 400  # blue candidates examined at most (largest first)


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
