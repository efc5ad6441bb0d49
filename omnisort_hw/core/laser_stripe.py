"""Sub-pixel centre line of red laser stripes, fast enough for one 1920x1920 frame per 20 ms.

How (all vectorised, no loop over pixels):

1. Candidates on strided copies. Every `stride`-th full row (all columns) and every
   `stride`-th full column (all rows) are taken; a thin stripe steeper than 45 degrees crosses
   every sampled row, a flatter one every sampled column. The redness
   `red = r - max(g, b) - 1.5 max(g - b, 0)` is computed with saturating 8-bit OpenCV
   operations (laser light is red and dominates coloured surfaces where it is bright; yellow,
   orange, tan and brown edges, whose green exceeds their blue, score low). Only green above
   blue is punished: a real sensor's blue filter passes a red line at 0.2 to 0.56 of red and
   its green filter hardly (measured on real photographs, docs/real_light.md), so a red line
   is magenta at its core, where a penalty on |g - b| split it into its two flanks. Only the
   sparse red pixels are visited: a candidate is the maximum of its scan
   line within +-4 px and stands above both samples 4 px away (a ridge, not a red area).
2. Adaptive thresholds: the redness noise is estimated from the image itself (RMS of
   neighbouring-pixel differences below their 99th percentile); candidates need 6 noise
   standard deviations (and at least 4 grey levels, 8-bit rounding). Then hysteresis relative
   to the image's own stripes: a point needs 0.08 and a chain's strong points 0.4 of the
   stripes' robust peak height (90th percentile of the candidates), and a chain needs 3 strong
   points of at least 30 grey levels (what any well exposed stripe has and what texture, edge
   colour fringes and JPEG ringing in laser-off images do not reach) or, for a faint stripe
   (far, dark surface, blurred), 16 points of which 80 % were seen as one straight stripe on
   every line of their fit window, which texture and edges do not do either.
3. Sub-pixel fit, only around candidates: a full-resolution window of 11 scan lines across the
   stripe is gathered; on every line the stripe's centre is the first moment of its redness
   profile above 30 % of its peak (unbiased for a symmetric profile, like a Gaussian fit, and
   unlike a three-point fit robust to JPEG chroma ringing and speckle); a weighted straight-line
   fit through those centres (peaks more than 1 px off dropped, one refit) gives the centre on
   the candidate's line and the local slope. A point is kept from the scan that cuts the
   stripe squarely (|slope| <= 1), so each stripe section is measured once. A line whose core
   clipped is centred on its half-height crossings instead, and a window that holds a kink
   (a cube's corner) is fitted on its straight half.
4. Chains: points are linked through a grid of one scan spacing (gaps of a cell bridged, for
   dashed, aliased stripes); chains that fail the tests above are dropped, and with them
   isolated specks of JPEG colour noise.
5. No laser here: an image none of whose chains is a line (long and thin; spots, marks and
   defocused patches are not) gives no points (`core.laser_presence`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from omnisort_hw.core.clipped_core import clipped_cores
from omnisort_hw.core.laser_colour import as_red_laser
from omnisort_hw.core.laser_presence import LinePresence, line_presence
from omnisort_hw.errors import InputError

_HALF = 4  # half-width (px) of the across-stripe window; stripes up to ~4 px wide
_ALONG = 5  # scan lines either side whose peaks are fitted with the candidate's
_CENTROID_HALF = 3  # samples either side of a profile's maximum used for its centre
_CENTROID_LEVEL = 0.3  # ... above this fraction of the peak height
_CHROMA_K = 1.5  # weight of g - b where green exceeds blue: yellow, orange and tan
_NOISE_K = 6.0  # candidate threshold in noise standard deviations
_FLOOR = 4.0  # grey levels: never below 8-bit quantisation and JPEG rounding
_LOW_FRACTION = 0.08  # hysteresis: a stripe point's height, of the stripes' robust peak
_HIGH_FRACTION = 0.4  # ... and a chain's strongest point
_STRONG_FLOOR = 30.0  # grey levels a chain must reach to be called a laser stripe
_MIN_CHAIN = 4  # points (one per scan line) a chain needs
_MIN_STRONG = 3  # ... of which strong
_LONG_CHAIN = 16  # points: a chain this long without strong points may be a faint stripe ...
_FAINT_AGREE = 0.8  # ... if this fraction of its points had a stripe on every window line


@dataclass(frozen=True)
class StripeStats:
    """What one extraction saw: noise, threshold and counts (for logs and error messages)."""

    noise: float
    low: float
    high: float
    candidates: int
    points: int
    heights: np.ndarray | None = None  # (points,) each point's stripe height (grey levels)
    # (points,) whether the point's fit window saw the stripe go on straight on both sides of
    # the point's line (False at a stripe's end or a kink), and its chain's label
    supported: np.ndarray | None = None
    chains: np.ndarray | None = None
    presence: LinePresence | None = None  # whether a laser line was seen at all


def check_bgr(image: np.ndarray, what: str = "image") -> np.ndarray:
    """A uint8 (H, W, 3) BGR image, or InputError saying what is wrong."""
    arr = np.asarray(image)
    if arr.dtype != np.uint8 or arr.ndim != 3 or arr.shape[2] != 3:
        raise InputError(
            f"{what}: expected an 8-bit BGR colour image (H, W, 3), got {arr.dtype} {arr.shape}"
        )
    return arr


def redness_u8(bgr: np.ndarray) -> np.ndarray:
    """The redness measure saturated to 0..255 (uint8, same rows and columns)."""
    b, g, r = cv2.split(bgr)
    red = cv2.subtract(r, cv2.max(g, b))
    return cv2.addWeighted(red, 1.0, cv2.subtract(g, b), -_CHROMA_K, 0.0)


def redness(bgr: np.ndarray) -> np.ndarray:
    """r - max(g, b) - k max(g - b, 0), signed float32, for arrays of any leading shape
    (..., 3)."""
    x = bgr.astype(np.float32)
    b, g, r = x[..., 0], x[..., 1], x[..., 2]
    return r - np.maximum(g, b) - _CHROMA_K * np.maximum(g - b, 0.0)


def _noise_sigma(bgr: np.ndarray, step: int) -> float:
    """Robust standard deviation of the signed redness, from differences of neighbouring pixels
    on every `step`-th row: RMS of the differences below their 99th percentile (edges and
    stripes are the top percent), over sqrt(2) (a difference carries two pixels' noise)."""
    rows = bgr[step // 2 :: step].astype(np.int16)
    red = rows[..., 2] - np.maximum(rows[..., 1], rows[..., 0])
    d = np.abs(np.diff(red, axis=1)).ravel().astype(np.float32)
    if d.size == 0:
        return 0.0
    cut = np.percentile(d, 99)
    core = d[d <= cut]
    return float(np.sqrt(np.mean(core * core)) / np.sqrt(2.0))


def _ridge_candidates(
    red: np.ndarray, axis: int, threshold: float
) -> tuple[np.ndarray, np.ndarray]:
    """Ridge pixels of a strided `redness_u8` image, scanning along `axis` (1: along rows).

    A candidate is red (> threshold), the maximum within +-_HALF samples along its scan line
    (so one crossing gives one candidate) and exceeds both samples _HALF away by `threshold`.
    Only the sparse set of red pixels is visited. Returns ((K, 2) (row, col) indices into
    `red`, (K,) ridge heights).
    """
    w = _HALF
    flat = np.flatnonzero(cv2.compare(red, threshold, cv2.CMP_GT).view(bool))  # type: ignore[call-overload]  # cv2 stubs: src2 may be a scalar
    r, c = np.divmod(flat, red.shape[1])
    pos = c if axis == 1 else r
    inside = (pos >= w) & (pos < red.shape[axis] - w)
    r, c = r[inside], c[inside]
    offs = np.arange(-w, w + 1)
    if axis == 1:
        line = red[r[:, None], c[:, None] + offs[None, :]]
    else:
        line = red[r[:, None] + offs[None, :], c[:, None]]
    line = line.astype(np.float32)
    height = line[:, w] - np.maximum(line[:, 0], line[:, -1])
    # the first maximum of the window (ties: the lower index)
    ok = (np.argmax(line, axis=1) == w) & (height > threshold)
    return np.stack([r[ok], c[ok]], axis=1), height[ok]


def _peak_centres(line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per profile (..., n): sub-pixel centre of its peak and the peak's height.

    The centre is the first moment of the background-subtracted profile above _CENTROID_LEVEL
    of the peak, within +-_CENTROID_HALF samples of the maximum. For a symmetric stripe profile
    it is unbiased, like a Gaussian fit, and it uses every sample of the stripe, so it is far
    less sensitive than a three-point fit to JPEG's chroma ringing and to laser speckle.
    """
    n = line.shape[-1]
    idx = np.arange(n, dtype=line.dtype)
    j = np.argmax(line[..., 1:-1], axis=-1) + 1
    background = line.min(axis=-1)
    peak = line.max(axis=-1) - background
    level = (background + _CENTROID_LEVEL * peak)[..., None]
    near = np.abs(idx - j[..., None]) <= _CENTROID_HALF
    wts = np.maximum(line - level, 0.0) * near
    total = wts.sum(axis=-1)
    pos = (wts @ idx) / np.maximum(total, 1e-9)
    return np.where(total > 0, pos, j.astype(line.dtype)), peak


def _weighted_line(
    x: np.ndarray, y: np.ndarray, wt: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Row-wise weighted least-squares line y = a + b x: (a, b, determinant)."""
    s0 = wt.sum(-1)
    sx = (wt * x).sum(-1)
    sy = (wt * y).sum(-1)
    sxx = (wt * x * x).sum(-1)
    sxy = (wt * x * y).sum(-1)
    det = s0 * sxx - sx * sx
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (sxx * sy - sx * sxy) / det
        b = (s0 * sxy - sx * sy) / det
    return a, b, det


def _red_channel(bgr: np.ndarray) -> np.ndarray:
    """The red channel as float32: the stripe's profile in an image of laser light alone."""
    return bgr[..., 2].astype(np.float32)


def _clipped_centres(raw: np.ndarray, win: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """Profile centres (..., samples) again where the stripe's core is clipped: the midpoint
    of the profile's two half-height crossings, interpolated on its flanks. A clipped core is
    a sample at 255, or, in a capture's laser-light image, a hole (0 in every channel between
    bright flanks: `core.laser_difference` zeroes what clipped in a frame). It carries no
    position, and the first moment above 30 % of the profile then leans to the grid or to one
    flank: up to half a pixel off (seen at a wall's bright near end in the `saturated` scene,
    where the capture's re-exposure left 1-2 % of the stripe clipped, as it allows). The
    flanks keep the position: a symmetric profile crosses any level below the clip at equal
    distances from its centre. Only profiles with a 255 or an all-zero sample next to their
    peak are looked at again (a map of an unclipped stripe pays for that test alone)."""
    n = win.shape[-1]
    j = np.argmax(win[..., 1:-1], axis=-1) + 1
    at = np.clip(j[..., None] + np.arange(-1, 2), 0, n - 1)  # the peak and its neighbours
    around = np.take_along_axis(raw, at[..., None], axis=-2)
    maybe = ((around[..., 2] == 255) | (around == 0).all(axis=-1)).any(axis=-1)
    if not maybe.any():
        return pos
    out = pos.copy()
    out[maybe] = _flank_centres(raw[maybe], win[maybe], j[maybe], pos[maybe])
    return out


def _flank_centres(raw: np.ndarray, win: np.ndarray, j: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """`_clipped_centres` for profiles (M, samples) with peak index j (M,): the half-height
    crossings' midpoint where a sample next to the peak is clipped, holes filled at the
    profile's peak first; `pos` elsewhere."""
    n = win.shape[-1]
    top = win.max(axis=-1, keepdims=True)
    bright = win >= 0.5 * top
    dark = (raw == 0).all(axis=-1)
    left_b = np.zeros_like(bright)  # a bright sample within 2 to the left (holes of 1-2 px)
    right_b = np.zeros_like(bright)
    for step in (1, 2):
        left_b[..., step:] |= bright[..., :-step]
        right_b[..., :-step] |= bright[..., step:]
    hole = dark & left_b & right_b
    clipped_sample = (raw[..., 2] == 255) | hole
    near = np.abs(np.arange(n) - j[..., None]) <= 1
    clipped = (clipped_sample & near).any(axis=-1)
    prof = np.where(hole, top, win)
    idx = np.arange(n - 1)
    half = (0.5 * (prof.min(axis=-1) + prof.max(axis=-1)))[..., None]
    above = prof >= half
    rise = ~above[..., :-1] & above[..., 1:]  # crossing between i and i + 1, going up
    fall = above[..., :-1] & ~above[..., 1:]  # ... going down
    left = np.where(rise & (idx < j[..., None]), idx, -1).max(axis=-1)
    right = np.where(fall & (idx >= j[..., None]), idx, n).min(axis=-1)
    li = np.clip(left, 0, n - 2)[..., None]
    ri = np.clip(right, 0, n - 2)[..., None]
    a0 = np.take_along_axis(prof, li, -1)[..., 0]
    a1 = np.take_along_axis(prof, li + 1, -1)[..., 0]
    b0 = np.take_along_axis(prof, ri, -1)[..., 0]
    b1 = np.take_along_axis(prof, ri + 1, -1)[..., 0]
    h = half[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        mid = 0.5 * (li[..., 0] + (h - a0) / (a1 - a0) + ri[..., 0] + (b0 - h) / (b0 - b1))
    ok = clipped & (left >= 0) & (right < n) & np.isfinite(mid)
    return np.where(ok, mid, pos)


_KINK_SIGMAS = 4.0  # half-window slopes this many standard deviations apart: a kink


def _one_sided_at_kinks(
    k: np.ndarray, pos: np.ndarray, wt: np.ndarray, a: np.ndarray, b: np.ndarray
) -> np.ndarray:
    """The centre on each window's own line, from the straight side where the window holds a
    kink. Near a cube's corner the lines past the corner (and those the blur rounds) lie on
    the other face; within the 1 px tolerance they pull the straight-line fit off the point's
    own face by up to half a pixel. Each half-window (its own line and the _ALONG lines on one
    side) is fitted alone; where the two slopes differ by more than _KINK_SIGMAS standard
    deviations (each half's from the lines it saw), the half that saw more lines, or on a tie
    the straighter one, gives the centre: past a corner or a fading end lines drop out or
    bend. Elsewhere the whole window's fit stands. The per-line noise is measured from this
    image: the lines' scatter about their fits, or, where larger (correlated errors such as
    JPEG's chroma bend straight windows as well), what the spread of all windows' slope
    differences implies, most windows being straight."""
    left = wt * (k <= 0)
    right = wt * (k >= 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        a_l, b_l, det_l = _weighted_line(k, pos, left)
        a_r, b_r, det_r = _weighted_line(k, pos, right)
        dev = np.abs(pos - (a[:, None] + b[:, None] * k))
    seen = wt > 0
    scatter = dev[seen & np.isfinite(dev)]
    if scatter.size < 20:
        return a
    n_l, n_r = (left > 0).sum(axis=1), (right > 0).sum(axis=1)
    both = (n_l >= 3) & (n_r >= 3) & (det_l > 0) & (det_r > 0)
    # slope variance of a half = sigma^2 / S_kk over the lines it saw
    s_l, s_r = _spread(k, left > 0), _spread(k, right > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.abs(b_l - b_r) / np.sqrt(1.0 / s_l + 1.0 / s_r)
    sigma = max(1.4826 * float(np.median(scatter)), 0.02)
    if both.sum() >= 20:
        sigma = max(sigma, 1.4826 * float(np.median(z[both])))
    with np.errstate(invalid="ignore"):
        kink = both & (z > _KINK_SIGMAS * sigma)
        straighter_l = _rms_about(k, pos, left, a_l, b_l) <= _rms_about(k, pos, right, a_r, b_r)
    use_l = (n_l > n_r) | ((n_l == n_r) & straighter_l)
    return np.where(kink, np.where(use_l, a_l, a_r), a)


def _spread(k: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """Sum of squared deviations of the seen lines' offsets k about their mean, per window."""
    n = np.maximum(seen.sum(axis=1), 1)
    mean = (seen * k).sum(axis=1) / n
    return np.maximum((seen * (k - mean[:, None]) ** 2).sum(axis=1), 1e-9)


def _rms_about(
    k: np.ndarray, pos: np.ndarray, wt: np.ndarray, a: np.ndarray, b: np.ndarray
) -> np.ndarray:
    """Weighted RMS of each window's centres about its line a + b k."""
    r2 = np.where(wt > 0, (pos - (a[:, None] + b[:, None] * k)) ** 2, 0.0)
    return np.sqrt(r2.sum(axis=1) / np.maximum((wt > 0).sum(axis=1), 1))


def _fit_windows(
    bgr: np.ndarray, centres: np.ndarray, across_u: bool, threshold: float, light_only: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sub-pixel centres for candidate pixels (v, u) of one scan direction.

    The across-stripe peak is fitted on the candidate's scan line and on _ALONG lines either
    side; a weighted straight-line fit of those peaks (robust: one pass drops peaks more than
    1 px off) gives the centre on the candidate's line with the noise of ~2 _ALONG + 1 lines,
    and the local slope, which decides whether this scan cut the stripe squarely (|slope| <= 1).
    `across_u`: scan lines are rows (profiles along u), else columns (along v). `light_only`:
    profiles are the red channel, else the redness (see `laser_stripe_points`).
    Returns (points (N, 2) as (u, v), stripe height above background (N,), whether every
    line of the window agreed with the fit (N,), keep mask, whether the stripe went on
    straight on both sides of the candidate's line (N,), how many lines saw it (N,)).
    """
    h, w = bgr.shape[:2]
    n = centres.shape[0]
    reach = _HALF + _ALONG
    off_a = np.arange(-reach, reach + 1)
    off_t = np.arange(-_ALONG, _ALONG + 1)
    v0, u0 = centres[:, 0], centres[:, 1]
    if across_u:
        vv = np.clip(v0[:, None, None] + off_t[None, :, None], 0, h - 1)
        uu = np.clip(u0[:, None, None] + off_a[None, None, :], 0, w - 1)
    else:
        vv = np.clip(v0[:, None, None] + off_a[None, None, :], 0, h - 1)
        uu = np.clip(u0[:, None, None] + off_t[None, :, None], 0, w - 1)
    flat = (vv * w + uu).astype(np.intp)
    # (N, lines, samples): scan lines x across-stripe samples, clipped as in the candidate stage
    measure = _red_channel if light_only else redness
    raw = np.take(bgr.reshape(-1, 3), flat, axis=0)
    win = np.maximum(measure(raw), 0.0)
    pos, height = _peak_centres(win)
    pos = _clipped_centres(raw, win, pos) - reach
    k = off_t.astype(float)[None, :]
    wt = np.where(height > 0.5 * threshold, height, 0.0)
    a, b, det = _weighted_line(k, pos, wt)
    with np.errstate(invalid="ignore"):
        resid = np.abs(pos - (a[:, None] + b[:, None] * k))
    wt = np.where(resid <= 1.0, wt, 0.0)
    a, b, det = _weighted_line(k, pos, wt)
    a = _one_sided_at_kinks(k, pos, wt, a, b)
    centre_h = height[:, _ALONG]
    # windows cut by the image border would be padded: no measurement there
    lines_at, samples_at = (v0, u0) if across_u else (u0, v0)
    n_lines, n_samples = (h, w) if across_u else (w, h)
    inside = (lines_at >= _ALONG) & (lines_at < n_lines - _ALONG)
    inside &= (samples_at >= reach) & (samples_at < n_samples - reach)
    ok = (
        inside
        & (det > 0)
        & ((wt > 0).sum(axis=1) >= 3)
        & (centre_h > threshold)
        & (np.abs(a) <= 1.5)
        & (np.abs(b) <= 1.0 if across_u else np.abs(b) < 1.0)
    )
    a = np.where(ok, a, 0.0)
    pts = np.empty((n, 2))
    if across_u:
        pts[:, 0] = u0 + a
        pts[:, 1] = v0
    else:
        pts[:, 0] = u0
        pts[:, 1] = v0 + a
    # the stripe goes on, straight, on both sides of the candidate's line (not an end, not a
    # kink): at least half the lines on each side and the line itself agree with the fit
    seen = wt > 0
    typical = np.where(seen, height, 0.0).sum(axis=1) / np.maximum(seen.sum(axis=1), 1)
    seen &= height >= 0.5 * typical[:, None]  # noise past an end is no stripe going on
    half = 1
    both_sides = (seen[:, :_ALONG].sum(axis=1) >= half) & (
        seen[:, _ALONG + 1 :].sum(axis=1) >= half
    )
    both_sides &= seen[:, _ALONG]
    return pts, centre_h, seen.sum(axis=1) >= 2 * _ALONG, ok, both_sides, seen.sum(axis=1)


def _ghosts(
    pts_r: np.ndarray,
    seen_r: np.ndarray,
    pts_c: np.ndarray,
    seen_c: np.ndarray,
    sup_r: np.ndarray,
    sup_c: np.ndarray,
    ok_r: np.ndarray,
    ok_c: np.ndarray,
    spacing: int,
) -> None:
    """Where a row scan and a column scan measured the stripe within one scan spacing,
    one of them cut it along its length: at the end of a flat stripe a row scan sees the
    stripe's end as a short steep ridge a few lines tall (its thickness) and measures it up to
    a pixel off. The point whose window saw the stripe on fewer lines is no interior point
    (`sup_r` / `sup_c` cleared in place)."""
    if not len(pts_r) or not len(pts_c):
        return
    from scipy.spatial import cKDTree

    dist, j = cKDTree(pts_c).query(pts_r, distance_upper_bound=max(1.5, float(spacing)))
    pair = np.isfinite(dist)
    i_r = np.flatnonzero(pair)
    i_c = j[pair]
    rows_lose = seen_r[i_r] < seen_c[i_c]
    idx_r = np.flatnonzero(ok_r)[i_r[rows_lose]]
    idx_c = np.flatnonzero(ok_c)[i_c[~rows_lose & (seen_c[i_c] < seen_r[i_r])]]
    sup_r[idx_r] = False
    sup_c[idx_c] = False


def _keep_chains(
    points: np.ndarray,
    strong: np.ndarray,
    consistent: np.ndarray,
    shape: tuple[int, int],
    cell: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Hysteresis on chains: points are linked through a grid of `cell`-px cells (one scan-line
    spacing; neighbouring cells and one-cell gaps link, so short gaps of dashed stripes are
    bridged and specks a few spacings away are not); a chain survives if it has at least
    _MIN_CHAIN points, _MIN_STRONG of them strong, or, for a faint stripe (far away, dark or
    diluted by blur), if it is long (_LONG_CHAIN points) and nearly all its points were seen
    as one straight stripe on every line of their fit window, which texture does not do.
    Returns (keep mask, each point's chain label)."""
    if points.shape[0] == 0:
        return np.zeros(0, dtype=bool), np.zeros(0, dtype=np.int64)
    h, w = shape
    gh, gw = h // cell + 1, w // cell + 1
    gi = np.clip((points[:, 1] / cell).astype(np.int64), 0, gh - 1)
    gj = np.clip((points[:, 0] / cell).astype(np.int64), 0, gw - 1)
    occ = np.zeros((gh, gw), np.uint8)
    occ[gi, gj] = 1
    linked = cv2.dilate(occ, np.ones((3, 3), np.uint8))
    n_lab, labels = cv2.connectedComponents(linked, connectivity=8)
    lab = labels[gi, gj]
    count = np.bincount(lab, minlength=n_lab)
    has_strong = np.bincount(lab, weights=strong.astype(float), minlength=n_lab) >= _MIN_STRONG
    agree = np.bincount(lab, weights=consistent.astype(float), minlength=n_lab)
    faint = (count >= _LONG_CHAIN) & (agree >= _FAINT_AGREE * count)
    good = (count >= _MIN_CHAIN) & (has_strong | faint)
    good[0] = False
    return good[lab], lab


def _with_clipped_cores(
    bgr: np.ndarray,
    red_rows: np.ndarray,
    mask: np.ndarray | None,
    low: float,
    high: float,
    stride: int,
    pts: np.ndarray,
    amp: np.ndarray,
    con: np.ndarray,
    sup: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The ridge points with those on a clipped core's flanks replaced by the core's centres
    (`core.clipped_core`); a core is as strong as a stripe gets. `red_rows`: the redness of
    every `stride`-th row, as the ridge search has it."""
    red_cols = redness_u8(np.ascontiguousarray(bgr[:, ::stride]))
    cores, goes_on, reach = clipped_cores(bgr, red_rows, red_cols, low, stride)
    if mask is not None and len(cores):
        m = mask.astype(bool, copy=False)
        cv, cu = np.rint(cores[:, 1]).astype(int), np.rint(cores[:, 0]).astype(int)
        inside = m[cv, cu]
        cores, goes_on = cores[inside], goes_on[inside]
    if not len(cores):
        return pts, amp, con, sup
    h, w = reach.shape
    pv = np.clip(np.rint(pts[:, 1]).astype(int), 0, h - 1)
    pu = np.clip(np.rint(pts[:, 0]).astype(int), 0, w - 1)
    keep = ~reach[pv, pu]
    n = len(cores)
    return (
        np.concatenate([pts[keep], cores]),
        np.concatenate([amp[keep], np.full(n, max(high, 255.0), amp.dtype)]),
        np.concatenate([con[keep], np.ones(n, bool)]),
        np.concatenate([sup[keep], goes_on]),
    )


def laser_stripe_points_stats(
    image_bgr: np.ndarray,
    mask: np.ndarray | None = None,
    stride: int | None = None,
    light_only: bool = False,
    color: str = "red",
) -> tuple[np.ndarray, StripeStats]:
    """`laser_stripe_points` plus the figures it used (noise, thresholds, counts)."""
    bgr = as_red_laser(check_bgr(image_bgr), color)
    h, w = bgr.shape[:2]
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape[:2] != (h, w):
            raise InputError(f"laser mask is {mask.shape[1]}x{mask.shape[0]}, image is {w}x{h}")
    s = stride if stride is not None else max(1, min(4, round(min(h, w) / 480)))
    noise = _noise_sigma(bgr, max(32, 32 * s))
    base = max(_NOISE_K * noise, _FLOOR)
    rows = np.ascontiguousarray(bgr[::s])  # every s-th row, all columns
    cols = cv2.resize(bgr, (-(-w // s), h), interpolation=cv2.INTER_NEAREST)  # every s-th col
    red_rows = redness_u8(rows)
    cand_r, height_r = _ridge_candidates(red_rows, 1, base)
    cand_c, height_c = _ridge_candidates(redness_u8(cols), 0, base)
    heights = np.concatenate([height_r, height_c])
    peak = float(np.percentile(heights, 90)) if heights.size else 0.0
    low = max(base, _LOW_FRACTION * peak)
    high = max(2.0 * base, _HIGH_FRACTION * peak, _STRONG_FLOOR)
    cand_r, cand_c = cand_r[height_r > low], cand_c[height_c > low]
    full_r = np.stack([cand_r[:, 0] * s, cand_r[:, 1]], axis=1)  # (v, u)
    full_c = np.stack([cand_c[:, 0], cand_c[:, 1] * s], axis=1)  # (v, u)
    if mask is not None:
        m = mask.astype(bool, copy=False)
        full_r = full_r[m[full_r[:, 0], full_r[:, 1]]]
        full_c = full_c[m[full_c[:, 0], full_c[:, 1]]]
    pts_r, amp_r, con_r, ok_r, sup_r, seen_r = _fit_windows(bgr, full_r, True, low, light_only)
    pts_c, amp_c, con_c, ok_c, sup_c, seen_c = _fit_windows(bgr, full_c, False, low, light_only)
    _ghosts(pts_r[ok_r], seen_r[ok_r], pts_c[ok_c], seen_c[ok_c], sup_r, sup_c, ok_r, ok_c, s)
    pts = np.concatenate([pts_r[ok_r], pts_c[ok_c]])
    amp = np.concatenate([amp_r[ok_r], amp_c[ok_c]])
    con = np.concatenate([con_r[ok_r], con_c[ok_c]])
    sup = np.concatenate([sup_r[ok_r], sup_c[ok_c]])
    if not light_only:  # a difference image has holes where the frames clipped, no white
        pts, amp, con, sup = _with_clipped_cores(
            bgr, red_rows, mask, low, high, s, pts, amp, con, sup
        )
    keep, chain = _keep_chains(pts, amp > high, con, (h, w), s)
    presence = line_presence(pts[keep], chain[keep], s)
    if not presence.present:  # spots, marks, blobs: no laser here (core.laser_presence)
        keep[:] = False
    pts = pts[keep]
    n_cand = int(full_r.shape[0] + full_c.shape[0])
    stats = StripeStats(
        noise, low, high, n_cand, int(pts.shape[0]), amp[keep], sup[keep], chain[keep], presence
    )
    return pts, stats


def laser_stripe_points(
    image_bgr: np.ndarray,
    mask: np.ndarray | None = None,
    stride: int | None = None,
    light_only: bool = False,
    color: str = "red",
) -> np.ndarray:
    """(N, 2) sub-pixel (u, v) centre points of laser stripes anywhere in the image.

    `mask` (H, W), nonzero where to look; `stride` the scan-line spacing (default: 4 px for a
    1920 px image, fewer for smaller images). An image without a stripe gives few or no points;
    callers that need a stripe check the count and raise with their own context.

    `light_only`: the image is laser light alone (a laser-on minus laser-off difference,
    `core.laser_difference`). Stripes are still found and chained by their redness, but each
    centre is fitted on the red channel: the redness's green and blue terms are there to
    reject coloured surfaces, which the difference has removed, and in a difference they carry
    no laser light, only noise (measured on the renders: the centres' scatter after 8 on/off
    pairs falls from 0.036 to 0.023 px RMS, what 32 pairs give with the redness).

    `color`: the laser's, one of `core.choices.LASER_COLORS` (`as_red_laser`).
    """
    return laser_stripe_points_stats(image_bgr, mask, stride, light_only, color)[0]


def stripe_interior(stats: StripeStats) -> np.ndarray:
    """Mask of the extracted points to measure distances with: those whose fit window saw the
    stripe go on straight on both sides of their line (on at least half the lines of each
    side), and every point of a piece where such points are fewer than half: a piece too
    short to have an interior, or a dashed stripe, whose gaps are no ends.

    At a stripe's end or a kink (a cube's corner, the tip of a V where two faces meet) the
    window sees the stripe on one side only or bent: the lens blur rounds the kink and drags
    the end past the surface's edge, and the straight-line fit there is biased by up to the
    blur's width (0.6 to 1 px measured at 1920 px, 0.15 to 0.2 % of the range). Those points
    are dropped where the same piece is mostly interior; a piece too short to have an
    interior keeps all of them, so a small obstacle stays on the map."""
    n = int(stats.points)
    if stats.supported is None or stats.chains is None or n == 0:
        return np.ones(n, bool)
    sup = np.asarray(stats.supported, bool)
    chains = np.asarray(stats.chains, np.int64)
    count = np.bincount(chains)
    interior = np.bincount(chains, weights=sup.astype(float), minlength=len(count))
    solid = interior >= 0.5 * count  # a dashed or broken stripe: its gaps are no ends
    return sup | ~solid[chains]
