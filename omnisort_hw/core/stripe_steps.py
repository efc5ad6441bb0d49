"""A stepped (aliased) laser stripe on a flat wall, put back on its line.

A thin stripe drawn by point sampling (a renderer's nearest texel, a binarised or strongly
undersampled image) is a staircase: along the wall its centre runs flat along one pixel row,
falls behind the true line, and jumps one row to catch up. Each flat run is a ramp about the
line, from half a step on one side to half a step on the other, so the line passes through the
middle of every riser. A least-squares line through the raw centres is biased whenever the
wall holds a fractional number of ramps: with three ramps of 4.8 mm over 1.3 m (the authors'
far wall) by up to 0.08 degree, and the band's centre follows the staircase whatever the
sub-pixel estimator.

What is done, on one wall's stripe points (already one great circle's inliers):

1. The points' signed distances r from their great circle and their positions along it; in
   order along the circle, the differences of neighbours. A step is a difference far outside
   the differences' own scatter (8 robust standard deviations, and at least 0.5 px); the
   stripe is a staircase only if it holds at least two steps, all of one sign and of one size
   (within a factor of 1.5), and each run between two steps a ramp that drifts by one step
   (its length times the common ramp slope, within the same factor), which noise, a kink or
   a stray point never do. Otherwise the points are returned unchanged (a smooth stripe,
   every real camera's).
2. The line is the straight line through the risers' midpoints (each riser's two ends
   extrapolated along the common ramp slope to the riser's position, and averaged).
3. Each point is moved across its circle by its ramp's deviation from that line (a common ramp
   slope and one offset per run, fitted to the points), so it keeps its own noise: the points
   scatter about the risers' line as they scattered about their ramp. A move larger than one
   step means the staircase was not one: the points are returned unchanged.
"""

from __future__ import annotations

import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.great_circles import _unit, pixel_scale

_STEP_SIGMAS = 8.0
_STEP_MIN_PX = 0.5
_STEP_SIZE_RATIO = 1.5
_MIN_STEPS = 2
_MIN_RUN = 3  # points a run between two steps needs (the end runs may be shorter)


def unstep_stripe(model: OcamModel, uv: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """The stripe points `uv` (N, 2) of one wall, moved onto the line through their risers'
    midpoints when they form a staircase about the great circle with `normal`; else `uv`."""
    if uv.shape[0] < 2 * _MIN_RUN * (_MIN_STEPS + 1):
        return uv
    rays = model.pixel_to_ray(uv)
    scale = pixel_scale(model, rays)
    r = (rays @ normal) * scale
    e1 = _unit(rays.mean(axis=0) - (rays.mean(axis=0) @ normal) * normal)
    e2 = np.cross(normal, e1)
    a = np.arctan2(rays @ e2, rays @ e1) * float(np.median(scale))  # px along the circle
    order = np.argsort(a)
    a_s, r_s = a[order], r[order]
    d = np.diff(r_s)
    med = float(np.median(d))
    sigma = 1.4826 * float(np.median(np.abs(d - med)))
    steps = np.flatnonzero(np.abs(d - med) > max(_STEP_SIGMAS * sigma, _STEP_MIN_PX))
    if steps.size < _MIN_STEPS:
        return uv
    sizes = d[steps] - med
    if not (np.all(sizes > 0) or np.all(sizes < 0)):
        return uv
    if np.abs(sizes).max() > _STEP_SIZE_RATIO * np.abs(sizes).min():
        return uv
    run = np.zeros(a_s.size, int)
    run[steps + 1] = 1
    run = np.cumsum(run)
    counts = np.bincount(run)
    if counts[1:-1].size and counts[1:-1].min() < _MIN_RUN:
        return uv  # runs between two steps are ramps, not a stray point's excursion
    # common ramp slope and one offset per run: r = c_run + s a
    n_runs = counts.size
    design = np.zeros((a_s.size, n_runs + 1))
    design[np.arange(a_s.size), run] = 1.0
    design[:, -1] = a_s
    coef, *_ = np.linalg.lstsq(design, r_s, rcond=None)
    c, s = coef[:-1], coef[-1]
    # A staircase's runs are its ramps: between two risers the ramp drifts by one step, so an
    # interior run spans one step over the ramp slope. Two spikes a few points apart (noise
    # and JPEG on a degraded stripe) pass the step tests but not this one.
    spacing = float(np.median(np.diff(a_s)))
    interior = np.arange(1, n_runs - 1)
    extent = np.array([np.ptp(a_s[run == k]) + spacing for k in interior])
    drift = np.abs(s) * extent
    step = float(np.mean(np.abs(sizes)))
    if interior.size and not np.all(
        (drift <= _STEP_SIZE_RATIO * step) & (drift * _STEP_SIZE_RATIO >= step)
    ):
        return uv
    # riser midpoints: both neighbouring runs' ramps at the riser's position, averaged
    a_mid = 0.5 * (a_s[steps] + a_s[steps + 1])
    r_mid = 0.5 * (c[run[steps]] + c[run[steps + 1]]) + s * a_mid
    line = np.polyfit(a_mid, r_mid, 1)
    ramp = c[run] + s * a_s
    shift = np.empty_like(r)
    shift[order] = np.polyval(line, a_s) - ramp
    if np.abs(shift).max() > np.abs(sizes).max():
        return uv  # a ramp is never more than one step off the risers' line
    moved = _unit(rays + (shift / scale)[:, None] * normal[None, :])
    return model.ray_to_pixel(moved)
