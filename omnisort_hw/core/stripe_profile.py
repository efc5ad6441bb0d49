"""The centre of a laser stripe's profile across it: one number per profile, vectorised.

A profile is the stripe's measure (its redness, or the red channel of laser light alone) on
the samples of one scan line across the stripe. Its centre is found in two steps:

1. **A first estimate:** the first moment of the profile above 30 % of its peak, within
   +-3 samples of the maximum. It uses every sample of the stripe, so it is far less
   sensitive than a three-point fit to JPEG's chroma ringing and to laser speckle. But a
   moment of thresholded samples leans toward the pixel grid: the threshold cuts the profile
   where no sample is, and its ends fall on samples unevenly on either side. That costs 0.02
   to 0.03 px on a clean stripe. On a colour camera's thin stripe it costs up to 0.33 px.
   There, the sensor sampled the red line on every other row or column only, and the
   demosaicing drew straight lines between those samples. The profile's peak and its crossings
   of the threshold then depend on where the line falls against the mosaic (0.21 px RMS over
   the phases, measured with `benchmarks/bench_stripe_effects.py`). A wall's stripe near a
   row keeps one phase along its whole length, so this is a bias that no averaging of frames
   removes.
2. **The rule for the mosaic: a moment over a window symmetric about the centre.** The
   profile is taken as the straight lines between its samples (what bilinear demosaicing
   made of the sensor's samples, and a close reading of any sampled profile), less its
   background. Its first moment is integrated exactly over a window centred on the last
   estimate, three times. The window's half-width is 1.3 times the half-width of the profile's
   run above the 30 % level, counted to the first sample below it on each side. For a
   Gaussian profile of sigma 1.2 to 2 px that is 2.2 to 2.7 sigma either side, 97 to 99 % of
   the stripe's light; JPEG's ringing further out stays outside. Two things make this
   unbiased:
   - the straight lines between a profile's samples keep the samples' first moment, which
     for any stripe wider than a pixel is the stripe's centre (to 0.001 px at sigma 1.2 px
     and a 2 px mosaic period);
   - a window symmetric about the centre adds nothing to either side.
   On the same frames the worst bias over the phases is 0.05 px (from 0.33), and 0.004 px
   without the mosaic (from 0.032).

   Where the profile is not a lone stripe's, the first estimate stands:
   - its run above the level is wider than a stripe's;
   - something else rises above the level inside the window (another arm of a kink, a
     second stripe);
   - a sample is clipped (its core is then centred on its flanks);
   - the rule would move it by more than half a sample. That is an asymmetric profile's move,
     for example a stripe's end seen along it. The mosaic's bias needs 0.33 px at most.

A clipped core is centred on its flanks instead (`laser_stripe._clipped_centres`), after this.
"""

from __future__ import annotations

import numpy as np

CENTROID_HALF = 3  # samples either side of a profile's maximum used for its first estimate
CENTROID_LEVEL = 0.3  # ... above this fraction of the peak height
WINDOW_SCALE = 1.3  # the symmetric window's half-width, of the run above CENTROID_LEVEL
ITERATIONS = 3  # the symmetric window re-centred on its own moment this many times
MAX_MOVE = 0.5  # samples: the most the rule moves a centre (module docstring)
MAX_RUN = CENTROID_HALF + 1  # samples: the widest stripe's run above the level, either side


def peak_centres(
    line: np.ndarray, saturated: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per profile (..., n): the sub-pixel centre of its peak (in samples, 0..n-1) by the
    first estimate and by the rule for the mosaic, and the peak's height above the
    profile's minimum. `saturated` (...,): profiles with a clipped sample, which keep their
    first estimate (their shape is not the stripe's; a clipped core is centred on its
    flanks after this)."""
    first, peak = _thresholded_moment(line)
    centre = _symmetric_moment(line, first, peak)
    return first, (centre if saturated is None else np.where(saturated, first, centre)), peak


def _thresholded_moment(line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The first estimate: the first moment of the profile above CENTROID_LEVEL of its peak,
    within +-CENTROID_HALF samples of its maximum; and the peak's height."""
    n = line.shape[-1]
    idx = np.arange(n, dtype=line.dtype)
    j = np.argmax(line[..., 1:-1], axis=-1) + 1
    background = line.min(axis=-1)
    peak = line.max(axis=-1) - background
    level = (background + CENTROID_LEVEL * peak)[..., None]
    near = np.abs(idx - j[..., None]) <= CENTROID_HALF
    wts = np.maximum(line - level, 0.0) * near
    total = wts.sum(axis=-1)
    pos = (wts @ idx) / np.maximum(total, 1e-9)
    return np.where(total > 0, pos, j.astype(line.dtype)), peak


def _symmetric_moment(line: np.ndarray, first: np.ndarray, peak: np.ndarray) -> np.ndarray:
    """The rule for the mosaic (module docstring, step 2), from the first estimate `first`."""
    n = line.shape[-1]
    idx = np.arange(n)
    background = line.min(axis=-1)
    above = line > (background + CENTROID_LEVEL * peak)[..., None]
    j = np.argmax(line[..., 1:-1], axis=-1) + 1
    left = np.where(~above & (idx < j[..., None]), idx, -1).max(axis=-1)
    right = np.where(~above & (idx > j[..., None]), idx, n).min(axis=-1)
    run = (right - left) / 2.0  # the half-width of the run above the level
    half = np.clip(WINDOW_SCALE * run, 1.0, (n - 1) / 2.0 - 1.0)
    integral = _LinearIntegral(line - background[..., None])
    centre = first.astype(np.float32)
    for _ in range(ITERATIONS):
        area, moment = integral.between(centre - half, centre + half)
        centre = np.where(area > 0, moment / np.maximum(area, 1e-9), centre)
        centre = np.clip(centre, half, n - 1 - half)  # the window stays on the profile
    # Only a lone stripe's profile: its run at most MAX_RUN samples either side (a wider one
    # is no stripe's: a line past the stripe's end, noise), and nothing else above the level
    # inside its window (another arm of a kink, a second stripe, a clipped core's hole).
    # Any other keeps its first estimate.
    inside = np.abs(idx - centre[..., None]) <= half[..., None]
    off_run = (idx <= left[..., None]) | (idx >= right[..., None])
    alone = ~(above & inside & off_run).any(axis=-1)
    # The rule corrects where the samples fall, which moves a centre by less than half a
    # sample; a larger move is an asymmetric profile's (a stripe's end seen along it), whose
    # moment walks down its slope: it keeps its first estimate.
    stripe = (peak > 0) & (run <= MAX_RUN) & alone & (np.abs(centre - first) <= MAX_MOVE)
    return np.where(stripe, centre, first).astype(line.dtype)


class _LinearIntegral:
    """The straight lines between the samples of profiles (..., n), integrated exactly: their
    area and first moment between any two positions (in samples). The integrals up to each
    sample are summed once; each window then costs a few look-ups, not a pass over the
    profile."""

    def __init__(self, prof: np.ndarray) -> None:
        p = np.asarray(prof, np.float32)
        self.n = p.shape[-1]
        s = np.arange(self.n - 1, dtype=np.float32)
        self.a, self.d = p[..., :-1], np.diff(p, axis=-1)  # each piece: a + d t, t in [0, 1]
        area = self.a + 0.5 * self.d
        moment = s * area + 0.5 * self.a + self.d / 3.0
        self.area_to = np.zeros(p.shape, np.float32)  # up to each sample
        self.moment_to = np.zeros(p.shape, np.float32)
        np.cumsum(area, axis=-1, out=self.area_to[..., 1:])
        np.cumsum(moment, axis=-1, out=self.moment_to[..., 1:])

    def to(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Area and first moment from sample 0 to position `x` (...,)."""
        x = np.clip(x, 0.0, self.n - 1.0)
        m = np.minimum(np.floor(x), self.n - 2).astype(np.intp)[..., None]
        t = x - m[..., 0]
        a = np.take_along_axis(self.a, m, -1)[..., 0]
        d = np.take_along_axis(self.d, m, -1)[..., 0]
        part = a * t + d * t * t / 2.0
        part_moment = m[..., 0] * part + a * t * t / 2.0 + d * t**3 / 3.0
        area = np.take_along_axis(self.area_to, m, -1)[..., 0] + part
        moment = np.take_along_axis(self.moment_to, m, -1)[..., 0] + part_moment
        return area, moment

    def between(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Area and first moment from `lo` to `hi` (...,)."""
        area_lo, moment_lo = self.to(lo)
        area_hi, moment_hi = self.to(hi)
        return area_hi - area_lo, moment_hi - moment_lo
