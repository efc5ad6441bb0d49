"""The centre of a laser stripe whose core clipped: measured where the clipped run is, not on
its two flanks.

A real colour sensor passes part of a red line to its blue (and a little to its green)
channel, so where the line is bright all three channels clip and the core is white: its
redness falls to zero between two red flanks, and a ridge search finds two lines, one on each
flank (8 to 10 px off on the development photographs, docs/real_light.md). The red channel
itself does not dip: it is clipped over a run that straddles the centre. So, on the scan lines
(every `stride`-th row and column, as the ridge search):

1. a core is a run of two samples or more whose red channel is clipped (>= CLIP) with
   laser-red samples (redness above the extraction's low threshold) within FLANK_PX beyond
   both ends, and a middle less red than both flanks (the core whitened; a line clipped in
   red alone stays red at its core, and the ridge search measures it): white
   paper, print or a glint, clipped but without red flanks, is no core;
2. a run cuts the stripe where the clipped run across it, through its middle, is at least
   as long: a stripe is longer than it is wide (a run along the stripe ends wherever the
   clipping stops, and its middle is anywhere across). A clipped spot of laser speckle, as
   long as it is wide, passes: a spot is no line, which the chains must tell;
3. the centre is the midpoint of the red channel's two crossings, on the flanks, of the level
   LEVEL of the way from its floor to its clip (a symmetric profile crosses any level at equal
   distances from its centre, and the flanks are not clipped): a straight cut through a
   straight stripe is centred on its centre line.

Points the ridge search found within the cores' reach (a disk about each core's centre, of
the core's length and FLANK_PX, and half a scan spacing, in radius) are the flanks: they are
dropped for the cores' centres.
"""

from __future__ import annotations

import cv2
import numpy as np

CLIP = 250  # a red sample at or above this is clipped (JPEG and white balance leave 255 lower)
FLANK_PX = 4  # red flanks must start within this many samples of a core's ends
MAX_CORE_PX = 64  # longer clipped runs are no stripe's core across
# A core is cut where the clipping runs on at least this many times as far across it. 2 was
# tried on the development photographs: it dropped short clipped sections of real stripes
# (the clipped run's distance from the core's centre grew from 0.26-0.50 to 0.52-1.4 px,
# medians per set) and still kept a clipped speckle spot.
ELONGATION = 1
# The level whose crossings on the flanks centre a core, from its floor to the clip: 0.5 was
# truer on a simulated Gaussian line (0.06 px RMS) but farther from the clipped run's centre on
# the real photographs (1.1 to 1.3 px, medians per set), whose flanks are not symmetric; 0.9
# the other way round (0.15 px RMS, 0.4 to 0.5 px); 0.75 keeps both within bounds.
LEVEL = 0.75


def _runs(clipped: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Runs of True along the rows of (n, m) `clipped`: (row, first, last) indices."""
    n, m = clipped.shape
    pad = np.zeros((n, m + 2), np.int8)
    pad[:, 1:-1] = clipped
    d = np.diff(pad, axis=1)
    rs, cs = np.nonzero(d == 1)
    _, ce = np.nonzero(d == -1)
    return rs, cs, ce - 1  # np.nonzero orders both by row then column: they pair up


def _cores_on_lines(
    red_ch: np.ndarray, redness: np.ndarray, low: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cores (rule 1) along the rows of (n, m) red-channel and redness samples: (row,
    sub-pixel centre, length) per core."""
    m = red_ch.shape[1]
    row, a, b = _runs(red_ch >= CLIP)
    length = b - a + 1
    ok = (a >= 1) & (b <= m - 2) & (length >= 2) & (length <= MAX_CORE_PX)
    row, a, b, length = row[ok], a[ok], b[ok], length[ok]
    offs = np.arange(1, FLANK_PX + 1)
    left = np.clip(a[:, None] - offs[None, :], 0, m - 1)
    right = np.clip(b[:, None] + offs[None, :], 0, m - 1)
    flank = np.minimum(
        redness[row[:, None], left].max(axis=1), redness[row[:, None], right].max(axis=1)
    ).astype(np.float32)
    middle = redness[row, (a + b) // 2].astype(np.float32)
    # red flanks, and a core less red than both: it whitened (a line clipped in red alone
    # stays red at its core, and the ridge search measures it)
    keep = (flank > low) & (middle < flank)
    row, a, b, length = row[keep], a[keep], b[keep], length[keep]
    return row, _half_level_centres(red_ch, row, a, b), length


def _half_level_centres(
    red_ch: np.ndarray, row: np.ndarray, a: np.ndarray, b: np.ndarray
) -> np.ndarray:
    """Rule 3: the midpoint of the red channel's crossings, round the core [a, b], of the
    level LEVEL of the way from its floor to its clip (on the flanks, where it is not clipped and a
    straight interpolation between two samples is good); the run's midpoint where a crossing
    is not within reach."""
    m = red_ch.shape[1]
    reach = MAX_CORE_PX // 2 + 16
    k = np.arange(-reach, reach + 1)
    mid = (a + b) // 2
    idx = np.clip(mid[:, None] + k[None, :], 0, m - 1)
    win = red_ch[row[:, None], idx].astype(np.float32)
    level = win.min(axis=1) + LEVEL * (255.0 - win.min(axis=1))
    below = win < level[:, None]
    j = np.arange(k.size)[None, :]
    inner_a, inner_b = (a - mid + reach)[:, None], (b - mid + reach)[:, None]
    left = np.where(below & (j < inner_a), j, -1).max(axis=1)
    right = np.where(below & (j > inner_b), j, k.size).min(axis=1)
    ok = (left >= 0) & (right < k.size)
    li, ri = np.clip(left, 0, k.size - 2), np.clip(right, 1, k.size - 1)
    n = np.arange(len(row))
    with np.errstate(divide="ignore", invalid="ignore"):
        x_l = li + (level - win[n, li]) / (win[n, li + 1] - win[n, li])
        x_r = ri - (level - win[n, ri]) / (win[n, ri - 1] - win[n, ri])
    centre = 0.5 * (x_l + x_r) - reach + mid
    return np.where(ok & np.isfinite(centre), centre, 0.5 * (a + b))


def _across(
    red_full: np.ndarray, v: np.ndarray, u: np.ndarray, along_rows: bool
) -> tuple[np.ndarray, np.ndarray]:
    """How far the clipping runs on from pixel (v, u) in the other direction, each way
    (rule 2), the pixel itself counted in both."""
    h, w = red_full.shape
    k = np.arange(-MAX_CORE_PX, MAX_CORE_PX + 1)
    if along_rows:  # the other direction: the column through (v, u)
        vv = np.clip(v[:, None] + k[None, :], 0, h - 1)
        line = red_full[vv, u[:, None]] >= CLIP
    else:
        uu = np.clip(u[:, None] + k[None, :], 0, w - 1)
        line = red_full[v[:, None], uu] >= CLIP
    mid = MAX_CORE_PX
    up = np.cumprod(line[:, mid:], axis=1).sum(axis=1)
    down = np.cumprod(line[:, mid::-1], axis=1).sum(axis=1)
    return up, down


def clipped_cores(
    bgr: np.ndarray, red_rows: np.ndarray, red_cols: np.ndarray, low: float, stride: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The centres (N, 2) (u, v) of clipped stripe cores on every `stride`-th row and column
    of `bgr`, whether the clipping goes on past the next scan line both ways (N,) bool, and a
    mask (H, W) bool of the cores' reach (see module doc); `red_rows` and `red_cols` are the
    redness of those rows (bgr[::stride]) and columns (bgr[:, ::stride]), `low` the
    extraction's low threshold."""
    h, w = bgr.shape[:2]
    red_full = bgr[..., 2]
    pts: list[np.ndarray] = []
    goes_on: list[np.ndarray] = []
    reach = np.zeros((h, w), np.uint8)
    for along_rows in (True, False):
        lines = np.arange(0, h if along_rows else w, stride)
        red_ch = red_full[lines] if along_rows else red_full[:, lines].T
        rd = red_rows if along_rows else red_cols.T
        idx, centre, length = _cores_on_lines(red_ch, rd, low)
        if idx.size == 0:
            continue
        line = lines[idx]
        pix = np.clip(np.rint(centre).astype(int), 0, (w if along_rows else h) - 1)
        v, u = (line, pix) if along_rows else (pix, line)
        up, down = _across(red_full, v, u, along_rows)
        cut = ELONGATION * length <= np.maximum(up + down - 1, 0)
        if not cut.any():
            continue
        c, ln, n = centre[cut], line[cut], length[cut]
        p = np.stack([c, ln], axis=1) if along_rows else np.stack([ln, c], axis=1)
        pts.append(p.astype(float))
        # the stripe goes on, clipped, past the next scan line either way: an interior point
        # (`laser_stripe.stripe_interior`); a short clipped patch (two stripes crossing, a
        # corner) is not
        goes_on.append(np.minimum(up[cut], down[cut]) > stride)
        # the cores' reach: about each core's centre, its run's length and FLANK_PX
        grow = (n + FLANK_PX).astype(int)
        for g in np.unique(grow):
            sel = grow == g
            mark = np.zeros((h, w), np.uint8)
            pu = np.clip(np.rint(p[sel, 0]).astype(int), 0, w - 1)
            pv = np.clip(np.rint(p[sel, 1]).astype(int), 0, h - 1)
            mark[pv, pu] = 1
            size = 2 * int(g) + int(stride) + 1
            kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
            np.maximum(reach, cv2.dilate(mark, kernel).astype(np.uint8), out=reach)
    if not pts:
        return np.zeros((0, 2)), np.zeros(0, bool), np.zeros((h, w), bool)
    return np.concatenate(pts), np.concatenate(goes_on), reach.astype(bool)
