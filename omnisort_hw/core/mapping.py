"""Mapping: laser pixels become millimetres on the laser plane.

A pixel's ray (camera model, then R_SC) meets the laser plane n.(p - (0, 0, -d)) = 0; that is
the whole of mapping. Points are reported in S and in the laser-plane frame L (origin where
the plane meets the Z axis of S, x_l along X_S projected into the plane). Segments are runs
of points that are contiguous around the emitter, split where consecutive points are further
apart than a gap; each segment's distance is the nearest horizontal distance from the camera
axis (the Z axis of S) to its points. With the points' pixels, a gap in a dashed stripe (a
faint stripe on a dark face, broken where the light is too weak) is bridged when it is no
more than what its pixel gap spans at the neighbours' own scale (mm per pixel): the same
surface continues. A jump in depth spans far more than its pixels imply and still splits.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.records import SegmentReply


@dataclass
class Segment:
    points_S: np.ndarray = field(repr=False)  # (N, 3) mm
    points_L: np.ndarray = field(repr=False)  # (N, 2) mm
    distance_mm: float  # nearest horizontal distance from the camera axis
    mean_distance_mm: float
    length_mm: float
    bearing_deg: float  # direction from the axis to the nearest point, about Z from +X

    def summary(self) -> SegmentReply:
        return SegmentReply(
            points=len(self.points_S),
            distance_mm=round(self.distance_mm, 2),
            mean_distance_mm=round(self.mean_distance_mm, 2),
            length_mm=round(self.length_mm, 2),
            bearing_deg=round(self.bearing_deg, 2),
            start_S_mm=[round(float(v), 2) for v in self.points_S[0]],
            end_S_mm=[round(float(v), 2) for v in self.points_S[-1]],
        )


def pixels_to_plane(pixels: np.ndarray, calib: SystemCalibration) -> np.ndarray:
    """(N, 2) laser pixels -> (N, 3) points in S on the laser plane (NaN where the ray misses)."""
    rays = calib.model.pixel_to_ray(np.asarray(pixels, float).reshape(-1, 2)) @ calib.R_SC.T
    n = calib.laser_normal
    denom = rays @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (-calib.laser_distance_mm * n[2]) / denom
    t = np.where(t > 0, t, np.nan)  # behind the viewpoint: no intersection
    return rays * t[:, None]


def plane_axes(calib: SystemCalibration) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Origin and unit axes (x_l, y_l) of the laser-plane frame L, in S."""
    n = calib.laser_normal
    origin = np.array([0.0, 0.0, -calib.laser_distance_mm])
    x_l = np.array([1.0, 0.0, 0.0]) - n[0] * n
    x_l /= np.linalg.norm(x_l)
    return origin, x_l, np.cross(n, x_l)


def to_plane_frame(points_S: np.ndarray, calib: SystemCalibration) -> np.ndarray:
    origin, x_l, y_l = plane_axes(calib)
    rel = points_S - origin
    return np.stack([rel @ x_l, rel @ y_l], axis=1)


_DASH_SPACINGS = 8  # a dash gap is bridged up to this many typical point spacings (pixels)
_DASH_SCALE = 1.5  # ... if it spans at most this many times what its pixels imply


def _dash_gaps(step: np.ndarray, px: np.ndarray, max_gap_mm: float) -> np.ndarray:
    """Which of the gaps (step > max_gap_mm, cyclic order) are breaks in one dashed stripe:
    the pixel gap is short (a few point spacings) and the gap in mm is what that pixel gap
    spans at the scale (mm/px) of the steps just before and after it."""
    dpx = np.linalg.norm(np.diff(px, axis=0, append=px[:1]), axis=1)
    small = step <= max_gap_mm
    if small.sum() < 2:
        return np.zeros(step.shape, bool)
    spacing = float(np.median(dpx[small]))
    scale = np.where(small & (dpx > 0), step / np.maximum(dpx, 1e-9), np.nan)
    before = np.roll(scale, 1)
    after = np.roll(scale, -1)
    with np.errstate(invalid="ignore"):
        local = np.fmax(before, after)  # NaN only when neither neighbour is a plain step
        return (
            (step > max_gap_mm)
            & (dpx <= _DASH_SPACINGS * spacing)
            & (step <= _DASH_SCALE * local * dpx)
        )


def segments(
    points_S: np.ndarray,
    calib: SystemCalibration,
    max_gap_mm: float = 25.0,
    min_points: int = 8,
    pixels: np.ndarray | None = None,
) -> list[Segment]:
    """Group plane points into contiguous runs around the emitter (see module docstring);
    `pixels` (N, 2), the points' pixels, let dashed stripes stay whole."""
    finite = np.all(np.isfinite(points_S), axis=1)
    pts = points_S[finite]
    px = None if pixels is None else np.asarray(pixels, float)[finite]
    if len(pts) == 0:
        return []
    L = to_plane_frame(pts, calib)
    order = np.argsort(np.arctan2(L[:, 1], L[:, 0]))
    pts, L = pts[order], L[order]
    px = None if px is None else px[order]
    step = np.linalg.norm(np.diff(L, axis=0, append=L[:1]), axis=1)
    # A lone point far from both neighbours (a speck of red) would split a run: drop it.
    lone = (step > max_gap_mm) & (np.roll(step, 1) > max_gap_mm)
    if lone.any():
        pts, L = pts[~lone], L[~lone]
        px = None if px is None else px[~lone]
        if len(pts) == 0:
            return []
        step = np.linalg.norm(np.diff(L, axis=0, append=L[:1]), axis=1)
    gap = step > max_gap_mm
    if px is not None:
        gap &= ~_dash_gaps(step, px, max_gap_mm)
    breaks = np.nonzero(gap)[0]
    if len(breaks) == 0:
        runs = [np.arange(len(pts))]
    else:
        # Start after the first break so a run that wraps through +-180 degrees stays whole.
        start = breaks[0] + 1
        rolled = np.roll(np.arange(len(pts)), -start)
        cut = np.nonzero(np.roll(gap, -start))[0] + 1
        runs = np.split(rolled, cut[:-1])
    out = []
    for idx in runs:
        if len(idx) < min_points:
            continue
        p = pts[idx]
        horiz = np.hypot(p[:, 0], p[:, 1])
        k = int(np.argmin(horiz))
        out.append(
            Segment(
                points_S=p,
                points_L=L[idx],
                distance_mm=float(horiz[k]),
                mean_distance_mm=float(horiz.mean()),
                length_mm=float(np.sum(np.linalg.norm(np.diff(L[idx], axis=0), axis=1))),
                bearing_deg=float(np.degrees(np.arctan2(p[k, 1], p[k, 0]))),
            )
        )
    return sorted(out, key=lambda s: s.distance_mm)
