"""Laser echoes: stripe points that cannot be direct hits of the laser.

The emitter sits on the Z axis of S and lights, along each direction in its plane, only the
first surface it meets. Two stripe points mapped to the same bearing about the emitter but
at clearly different ranges cannot both be lit directly: one is light that came some other
way, typically the stripe mirrored by a glossy floor (it maps nearer than the wall it comes
from) or by a shiny object. The direct hit is the brighter one (a reflection loses light);
the weaker one is dropped when its surface's strength there (the median over its points at
that bearing and range: speckle makes single points vary by tens of percent) is less than
`ECHO_RATIO` of the brightest surface's at that bearing and its range differs by more than
`RANGE_GAP`.
"""

from __future__ import annotations

import numpy as np

ECHO_RATIO = 0.5  # a reflection returns at most half the light (floors, lacquer, glass)
RANGE_GAP = 0.02  # relative range difference that is not the same surface (noise << 2 %)
BEARING_WINDOW_DEG = 0.5  # points within this bearing see the same emitter ray (> a pixel)


def direct_hits(points_S: np.ndarray, strength: np.ndarray) -> np.ndarray:
    """Mask of the (N, 3) plane points (S, mm; NaN rows kept) that may be direct hits."""
    pts = np.asarray(points_S, float).reshape(-1, 3)
    amp = np.asarray(strength, float).reshape(-1)
    keep = np.ones(len(pts), bool)
    ok = np.flatnonzero(np.all(np.isfinite(pts), axis=1))
    if ok.size < 2:
        return keep
    bearing = np.degrees(np.arctan2(pts[ok, 1], pts[ok, 0]))
    rng = np.hypot(pts[ok, 0], pts[ok, 1])
    order = np.argsort(bearing)
    b, r, a = bearing[order], rng[order], amp[ok][order]
    lo = np.searchsorted(b, b - BEARING_WINDOW_DEG, side="left")
    hi = np.searchsorted(b, b + BEARING_WINDOW_DEG, side="right")
    # A point's strength is the median over its own surface nearby (same bearing window,
    # same range): speckle makes single points flicker by tens of percent, surfaces do not.
    level = np.empty(len(b))
    for i in range(len(b)):  # one pass over points (hundreds), not pixels
        w = slice(lo[i], hi[i])
        same = np.abs(r[w] - r[i]) <= RANGE_GAP * r[i]
        level[i] = np.median(a[w][same])
    drop = np.zeros(len(b), bool)
    for i in range(len(b)):
        j = lo[i] + int(np.argmax(level[lo[i] : hi[i]]))
        weak = level[i] < ECHO_RATIO * level[j]
        drop[i] = weak and abs(r[i] - r[j]) > RANGE_GAP * r[j]
    keep[ok[order[drop]]] = False
    return keep


def floor_mirror_partners(
    points_S: np.ndarray,
    laser_normal: np.ndarray,
    laser_distance_mm: float,
    floor_normal: np.ndarray,
    floor_offset_mm: float,
) -> np.ndarray:
    """Where each laser-plane point (N, 3, S, mm) would have come from if it were the floor's
    mirror image of the stripe: the camera's ray through it goes on to the floor (n . x = k,
    n up), is reflected there and meets the laser plane again (NaN: the ray does not reach
    the floor beyond the plane, or the reflection leaves the plane)."""
    pts = np.asarray(points_S, float).reshape(-1, 3)
    n = np.asarray(floor_normal, float) / np.linalg.norm(floor_normal)
    m = np.asarray(laser_normal, float) / np.linalg.norm(laser_normal)
    c = -laser_distance_mm * m[2]  # the laser plane: m . x = c
    with np.errstate(divide="ignore", invalid="ignore"):
        t = floor_offset_mm / (pts @ n)  # the ray x = t p (t = 1 at the point) meets the floor
        foot = pts * t[:, None]
        out = pts - 2.0 * (pts @ n)[:, None] * n  # the ray's direction after the reflection
        s = (c - foot @ m) / (out @ m)
        partner = foot + s[:, None] * out
    bad = ~(t > 1.0) | ~(s > 0.0)
    partner[bad] = np.nan
    return partner


def floor_echoes(
    points_S: np.ndarray,
    laser_normal: np.ndarray,
    laser_distance_mm: float,
    floor_normal: np.ndarray,
    floor_offset_mm: float,
    seen_S: np.ndarray | None = None,
) -> np.ndarray:
    """Mask of the points that are the floor's mirror image of another stripe point seen
    (among `seen_S`, default the points themselves: a stripe point too imprecise to map, at a
    stripe's end, still shows that the laser lit its place).

    A point X and a point seen where X's floor-mirror partner Q lies (same emitter bearing
    within `BEARING_WINDOW_DEG`, range within `RANGE_GAP`) cannot both be direct hits: Q lies
    on the same emitter ray as X, beyond it, so X lit directly would shadow Q. Q seen lit
    explains X as its reflection, whatever their strengths (a glossy floor in front of a dim
    or grazing wall returns more than half its light). A mirror image whose direct stripe is
    hidden from the camera is not caught here."""
    pts = np.asarray(points_S, float).reshape(-1, 3)
    echo = np.zeros(len(pts), bool)
    ok = np.flatnonzero(np.all(np.isfinite(pts), axis=1))
    if ok.size < 2:
        return echo
    q = floor_mirror_partners(
        pts[ok], laser_normal, laser_distance_mm, floor_normal, floor_offset_mm
    )
    has_q = np.all(np.isfinite(q), axis=1)
    seen = pts[ok] if seen_S is None else np.asarray(seen_S, float).reshape(-1, 3)
    seen = seen[np.all(np.isfinite(seen), axis=1)]
    bearing = np.degrees(np.arctan2(seen[:, 1], seen[:, 0]))
    rng = np.hypot(seen[:, 0], seen[:, 1])
    order = np.argsort(bearing)
    b_sorted, r_sorted = bearing[order], rng[order]
    qb = np.degrees(np.arctan2(q[:, 1], q[:, 0]))
    qr = np.hypot(q[:, 0], q[:, 1])
    lo = np.searchsorted(b_sorted, qb - BEARING_WINDOW_DEG, side="left")
    hi = np.searchsorted(b_sorted, qb + BEARING_WINDOW_DEG, side="right")
    for i in np.flatnonzero(has_q):  # one pass over points (hundreds), not pixels
        near = np.abs(r_sorted[lo[i] : hi[i]] - qr[i]) <= RANGE_GAP * qr[i]
        echo[ok[i]] = bool(near.any())
    return echo
