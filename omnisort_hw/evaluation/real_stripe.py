"""How well a stripe extractor holds on a photograph of one laser line across a planar card.

No truth comes with a real photograph, so the reference is built from the photograph itself,
by a rule that does not share the extractor's assumptions (colour ratios, ridge tests):

1. The stripe's course: the pixels where the laser raises its channel above the surroundings
   by DOMINANCE grey levels more than the other two, fitted by a robust quadratic (the line
   on a plane, bent by the lens).
2. Across each scan line (columns for a flat stripe, rows for a steep one), inside a band of
   BAND_PX about that course, the profile of the laser channel less the mean of the other two
   (zero on grey paper and print, whatever their brightness, so a square's edge in the band
   is no step), above its median: the centre is the midpoint of the half-maximum crossings
   of the run that holds its maximum. A clipped sample of the laser channel counts as the
   profile's maximum: the colour filters' crosstalk whitens a bright core, where the
   difference falls, and the clipped run is then one plateau, centred.
3. A cubic fitted to those centres with outliers trimmed (a plane's line up to the lens's
   distortion) is the reference line; the lines whose centre agrees with it within 1.5 px
   are the reference's extent.

The card: its inner corners (`cv2.findChessboardCornersSBWithMeta`, any size), grown by one
square on every side, are "the board". A photograph where no board is found is judged along
the stripe's extent.

Figures per photograph (`judge`): the share of the extractor's points off the stripe (farther
than `tol` from the reference line: a quarter of the stripe's median width at half maximum, at
least 2 px, so a point on a flank of a clipped core is off), on the board and anywhere; the
coverage (the share of reference lines on the board with a point on the stripe within 2 px
along it); and where the core clipped, each point's distance from the centre of the clipped
run and the share of clipped lines measured more than once (a stripe split at its flanks).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.polynomial import Polynomial

LASER_CHANNEL = {"red": 2, "green": 1, "blue": 0}  # BGR index of each laser colour
DOMINANCE = 25  # grey levels the laser raises its channel more than both others, for the course
BAND_PX = 30  # half-width of the band about the course where a line's profile is read
MIN_PEAK = 30.0  # grey levels a line's profile must rise above its floor to be measured
CLIP = 250  # a sample at or above this is clipped (JPEG leaves 255 a few levels lower)
ALONG_PX = 2.0  # a reference line is covered by a point within this distance along it


@dataclass
class ReferenceStripe:
    """The stripe measured on the photograph (module doc): per scan line its centre."""

    steep: bool  # scan lines are rows (the stripe runs along v), else columns
    lines: np.ndarray  # (n,) scan line index (u for a flat stripe, v for a steep one)
    centre: np.ndarray  # (n,) centre across the line, px
    width: np.ndarray  # (n,) width at half maximum, px
    clip_centre: np.ndarray  # (n,) centre of the clipped run (NaN where not clipped)
    line: Polynomial  # cubic: centre as a function of the line index

    def across(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(along, across) coordinates of points (N, 2) (u, v) in the scan's frame."""
        p = np.asarray(pts, float).reshape(-1, 2)
        return (p[:, 1], p[:, 0]) if self.steep else (p[:, 0], p[:, 1])

    def distance(self, pts: np.ndarray) -> np.ndarray:
        """(N,) distance (px) of points (u, v) from the reference line, square to it."""
        along, across = self.across(pts)
        slope = self.line.deriv()(along)
        return np.abs(across - self.line(along)) / np.sqrt(1.0 + slope**2)

    @property
    def tol(self) -> float:
        return max(2.0, 0.25 * float(np.median(self.width)))


def _laser_hat(bgr: np.ndarray, channel: int) -> np.ndarray:
    """(H, W) int16: how much more `channel` rises above its surroundings than the other two
    (white top-hats wider than any stripe)."""
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * BAND_PX + 1,) * 2)
    hat = cv2.morphologyEx(bgr, cv2.MORPH_TOPHAT, kernel).astype(np.int16)
    return hat[..., channel] - np.delete(hat, channel, axis=2).max(axis=2)


def _course(bgr: np.ndarray, channel: int) -> tuple[bool, np.ndarray] | None:
    """(steep, quadratic coefficients of the course) from the pixels where the laser raises
    its channel above the surroundings by DOMINANCE more than the other two (white top-hats
    wider than any stripe: a white or clipped core raises all three and drops out, its flanks
    stay; white paper and print raise all three alike)."""
    mask = _laser_hat(bgr, channel) > DOMINANCE
    v, u = np.nonzero(mask)
    if u.size < 50:
        return None
    extent = np.percentile(np.stack([u, v]), [5, 95], axis=1)  # stray pixels do not count
    steep = float(extent[1, 1] - extent[0, 1]) > float(extent[1, 0] - extent[0, 0])
    along, across = (v, u) if steep else (u, v)
    keep = np.ones(along.size, bool)
    coeffs = np.zeros(3)
    for _ in range(4):  # trimmed fits: laser-coloured things off the line drop out
        coeffs = np.polyfit(along[keep], across[keep], 2)
        r = np.abs(across - np.polyval(coeffs, along))
        keep = r <= max(3.0 * float(np.median(r[keep])) * 1.4826, 4.0)
    return steep, coeffs


def reference_stripe(bgr: np.ndarray, colour: str = "red") -> ReferenceStripe | None:
    """The reference stripe of a photograph (module doc), or None when no laser line shows."""
    channel = LASER_CHANNEL[colour]
    course = _course(bgr, channel)
    if course is None:
        return None
    steep, c2 = course
    x = bgr.astype(np.float32)
    own = x[..., channel]
    lum = own - np.delete(x, channel, axis=2).mean(axis=2)
    lum[own >= CLIP] = np.inf  # a clipped sample is laser light at its brightest
    if steep:
        lum = lum.T
    n_lines, n_across = lum.shape[1], lum.shape[0]
    lines = np.arange(n_lines)
    mid = np.polyval(c2, lines)
    span = 2 * BAND_PX + 1
    if n_across < span:
        return None
    # the band about the course, moved inside the image where the course runs near its edge
    base = np.clip(np.rint(mid).astype(int) - BAND_PX, 0, n_across - span)
    inside = (mid >= 0) & (mid <= n_across - 1)
    lines, base = lines[inside], base[inside]
    idx = base[:, None] + np.arange(span)[None, :]
    prof = lum[idx, lines[:, None]]  # (n, samples)
    clipped = ~np.isfinite(prof)
    top = np.where(clipped, -np.inf, prof).max(axis=1)
    peak = np.where(clipped.any(axis=1), np.maximum(top, 255.0 / 2), top)
    prof = np.where(clipped, peak[:, None], prof)
    floor = np.median(prof, axis=1)
    half = (0.5 * (floor + peak))[:, None]
    j = np.argmax(prof, axis=1)
    n = prof.shape[1]
    k = np.arange(n)[None, :]
    above = prof >= half
    # the run above half maximum that holds the maximum: its first and last samples
    below_left = np.where(~above & (k < j[:, None]), k, -1).max(axis=1)
    below_right = np.where(~above & (k > j[:, None]), k, n).min(axis=1)
    ok = (peak - floor > MIN_PEAK) & (below_left >= 0) & (below_right < n)
    bl = np.clip(below_left, 0, n - 2)
    br = np.clip(below_right, 1, n - 1)
    r = np.arange(len(lines))
    h = half[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        left = bl + (h - prof[r, bl]) / (prof[r, bl + 1] - prof[r, bl])
        right = br - (h - prof[r, br]) / (prof[r, br - 1] - prof[r, br])
    centre = 0.5 * (left + right) + base
    width = right - left
    run_in = clipped & (k > below_left[:, None]) & (k < below_right[:, None])
    n_clip = run_in.sum(axis=1)
    first = np.where(run_in, k, n).min(axis=1)
    last = np.where(run_in, k, -1).max(axis=1)
    clip_centre = np.where(n_clip >= 2, 0.5 * (first + last) + base, np.nan)
    ok &= np.isfinite(centre) & (width > 0)
    if ok.sum() < 20:
        return None
    lines, centre, width, clip_centre = lines[ok], centre[ok], width[ok], clip_centre[ok]
    keep = np.ones(lines.size, bool)
    line = Polynomial.fit(lines, centre, 3)
    for _ in range(4):
        line = Polynomial.fit(lines[keep], centre[keep], 3)
        keep = np.abs(centre - line(lines)) <= 1.5
    if keep.sum() < 20:
        return None
    return ReferenceStripe(steep, lines[keep], centre[keep], width[keep], clip_centre[keep], line)


def board_hull(bgr: np.ndarray) -> np.ndarray | None:
    """The card's checkered area (K, 2): the convex hull of its inner corners grown by one
    square on every side (each border row and column extrapolated from its neighbour; a
    stripe often runs across the outer squares), or None when no board is found."""
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    flags = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_LARGER
    found, corners, meta = cv2.findChessboardCornersSBWithMeta(grey, (5, 4), flags=flags)
    if not found:
        return None
    g = corners.reshape(*meta.shape[:2], 2).astype(np.float64)
    g = np.concatenate([2 * g[:1] - g[1:2], g, 2 * g[-1:] - g[-2:-1]], axis=0)
    g = np.concatenate([2 * g[:, :1] - g[:, 1:2], g, 2 * g[:, -1:] - g[:, -2:-1]], axis=1)
    return cv2.convexHull(g.reshape(-1, 2).astype(np.float32)).reshape(-1, 2)


def _in_hull(hull: np.ndarray | None, pts: np.ndarray) -> np.ndarray:
    if hull is None:
        return np.ones(len(pts), bool)
    h = hull.reshape(-1, 1, 2).astype(np.float32)
    return np.array(
        [cv2.pointPolygonTest(h, (float(u), float(v)), False) >= 0 for u, v in pts], bool
    )


def judge(ref: ReferenceStripe, hull: np.ndarray | None, pts: np.ndarray) -> dict[str, Any]:
    """The figures of extracted points (N, 2) (u, v) against the reference (module doc)."""
    pts = np.asarray(pts, float).reshape(-1, 2)
    tol = ref.tol
    d = ref.distance(pts)
    along, _ = ref.across(pts)
    lo, hi = float(ref.lines.min()), float(ref.lines.max())
    on_extent = (along >= lo - ALONG_PX) & (along <= hi + ALONG_PX)
    on_board = _in_hull(hull, pts) & on_extent
    on = d <= tol
    ref_pts = (
        np.stack([ref.centre, ref.lines], 1) if ref.steep else np.stack([ref.lines, ref.centre], 1)
    )
    board_lines = _in_hull(hull, ref_pts)
    covered = np.zeros(ref.lines.size, bool)
    if on.any():
        good = np.sort(along[on])
        i = np.clip(np.searchsorted(good, ref.lines), 1, len(good) - 1) if len(good) > 1 else None
        if i is None:
            covered = np.abs(ref.lines - good[0]) <= ALONG_PX
        else:
            near = np.minimum(np.abs(good[i] - ref.lines), np.abs(good[i - 1] - ref.lines))
            covered = near <= ALONG_PX
    out: dict[str, Any] = {
        "tol_px": round(tol, 2),
        "stripe_width_px": round(float(np.median(ref.width)), 1),
        "points": len(pts),
        "points_on_board": int(on_board.sum()),
        "off_on_board": round(float((~on[on_board]).mean()), 4) if on_board.any() else None,
        "off_anywhere": round(float((~on).mean()), 4) if len(pts) else None,
        "coverage": round(float(covered[board_lines].mean()), 4) if board_lines.any() else None,
    }
    clip = np.isfinite(ref.clip_centre) & board_lines
    if clip.sum() >= 5:
        line_of = np.rint(along).astype(int)
        pos = {int(x): i for i, x in enumerate(ref.lines)}
        at = np.array([pos.get(int(x), -1) for x in line_of], dtype=np.intp)
        hit = (at >= 0) & on_extent
        hit[hit] &= clip[at[hit]]
        hit[hit] &= d[hit] <= ref.width[at[hit]]  # the stripe's points, not phantoms elsewhere
        _, across = ref.across(pts)
        dist = np.abs(across[hit] - ref.clip_centre[at[hit]])
        per_line = np.bincount(at[hit], minlength=ref.lines.size)[clip]
        seen = per_line > 0
        out["clipped_lines"] = int(clip.sum())
        out["clipped_points"] = int(hit.sum())
        out["clipped_median_px"] = round(float(np.median(dist)), 2) if dist.size else None
        out["clipped_p95_px"] = round(float(np.percentile(dist, 95)), 2) if dist.size else None
        out["clipped_split"] = round(float((per_line[seen] > 1).mean()), 4) if seen.any() else None
    return out


def _mean(rows: list[dict[str, Any]], key: str, how: str = "mean") -> float | None:
    vals = [float(r[key]) for r in rows if r.get(key) is not None]
    if not vals:
        return None
    v = np.asarray(vals)
    return round(float(v.mean() if how == "mean" else v.max() if how == "max" else v.min()), 4)


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """One set's figures from `judge`'s per photograph: means and the worst photograph."""
    return {
        "photos": len(rows),
        "with_board": sum(r.get("coverage") is not None for r in rows),
        "off_on_board_mean": _mean(rows, "off_on_board"),
        "off_on_board_max": _mean(rows, "off_on_board", "max"),
        "off_anywhere_mean": _mean(rows, "off_anywhere"),
        "coverage_mean": _mean(rows, "coverage"),
        "coverage_min": _mean(rows, "coverage", "min"),
        "clipped_photos": sum("clipped_lines" in r for r in rows),
        "clipped_median_px": _mean(rows, "clipped_median_px"),
        "clipped_p95_px_max": _mean(rows, "clipped_p95_px", "max"),
        "clipped_split_mean": _mean(rows, "clipped_split"),
    }
