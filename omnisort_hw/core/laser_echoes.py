"""Laser echoes: stripe points that cannot be direct hits of the laser.

The emitter sits on the Z axis of S and lights, along each direction in its plane, only the
first surface it meets. Two stripe points mapped to the same bearing about the emitter but
at clearly different ranges cannot both be lit directly: one is light that came some other
way, typically the stripe mirrored by a glossy floor (it maps nearer than the wall it comes
from) or by a shiny object. The direct hit is the brighter one (a reflection loses light);
the weaker one is dropped when it is less than `ECHO_RATIO` of the brightest point at that
bearing and its range differs by more than `RANGE_GAP` of it.
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
    drop = np.zeros(len(b), bool)
    for i in range(len(b)):  # one pass over points (hundreds), not pixels
        j = lo[i] + int(np.argmax(a[lo[i] : hi[i]]))
        weak = a[i] < ECHO_RATIO * a[j]
        drop[i] = weak and abs(r[i] - r[j]) > RANGE_GAP * r[j]
    keep[ok[order[drop]]] = False
    return keep
