"""What a real colour camera does to light, measured on photographs of a laser line across a
checkerboard card: the numbers the simulator's camera effects take their ranges from
(`sim_backend.camera_effects`, docs/real_light.md).

- `crosstalk`: how much each other channel rises per grey level the laser raises its own,
  across unclipped stripes (a straight-line fit of each channel against the laser's channel
  over the stripe's band, per scan line; the median over lines);
- `chromatic_shift`: how far the red and blue images of the card's inner corners lie from the
  green ones along the radius, as a slope in pixels at the image's corner (corners found in
  each channel alone; a least-squares line through the origin of shift against radius);
- `halo`: the laser channel beside a clipped core, as a share of the clip level above the
  band's floor, at distances from the core's half-maximum edge (medians over clipped lines).
"""

from __future__ import annotations

import cv2
import numpy as np

from omnisort_hw.evaluation.real_stripe import BAND_PX, LASER_CHANNEL, ReferenceStripe

HALO_AT_PX = (2, 4, 8, 16, 32)
_FLAGS = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY


def _bands(
    bgr: np.ndarray, ref: ReferenceStripe, half: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(profiles (n, 2 half + 1, 3) across the stripe, the centre's offset in them (n,), the
    index of the reference lines they belong to (n,)), for the lines whose band fits."""
    x = bgr.astype(np.float32)
    if ref.steep:
        x = x.transpose(1, 0, 2)
    lo = np.rint(ref.centre).astype(int) - half
    ok = (lo >= 0) & (lo + 2 * half + 1 <= x.shape[0])
    idx = lo[ok, None] + np.arange(2 * half + 1)[None, :]
    prof = x[idx, ref.lines[ok, None]]
    return prof, ref.centre[ok] - lo[ok], np.flatnonzero(ok)


def crosstalk(bgr: np.ndarray, ref: ReferenceStripe, colour: str) -> dict[str, float] | None:
    """Per other channel (by name), its rise per grey level of the laser's channel across the
    photograph's unclipped stripe lines (median), or None without 20 such lines."""
    ch = LASER_CHANNEL[colour]
    prof, _, _ = _bands(bgr, ref, BAND_PX)
    own = prof[..., ch]
    rise = own.max(axis=1) - np.median(own, axis=1)
    use = (own.max(axis=1) < 250) & (rise > 60)
    if use.sum() < 20:
        return None
    own = own[use]
    d = own - own.mean(axis=1, keepdims=True)
    out = {}
    for name, k in LASER_CHANNEL.items():
        if k == ch:
            continue
        other = prof[use][..., k]
        slope = (d * (other - other.mean(axis=1, keepdims=True))).sum(axis=1) / (d * d).sum(axis=1)
        out[name] = float(np.median(slope))
    return out


def chromatic_shift(bgr: np.ndarray) -> dict[str, float] | None:
    """Red's and blue's radial shift from green at the image's corner (px, outward positive),
    from the card's inner corners found in each channel, or None without a card in all
    three."""
    h, w = bgr.shape[:2]
    flags = _FLAGS | cv2.CALIB_CB_LARGER
    found, green, meta = cv2.findChessboardCornersSBWithMeta(bgr[..., 1], (5, 4), flags=flags)
    if not found:
        return None
    size = (meta.shape[1], meta.shape[0])
    g = green.reshape(-1, 2)
    centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    radial = g - centre
    r = np.linalg.norm(radial, axis=1)
    unit = radial / np.maximum(r, 1e-9)[:, None]
    corner = float(np.hypot(*centre))
    out = {}
    for name, k in (("red", 2), ("blue", 0)):
        ok, pts = cv2.findChessboardCornersSB(bgr[..., k], size, flags=_FLAGS)
        if not ok:
            return None
        p = pts.reshape(-1, 2)
        if np.linalg.norm(p[0] - g[0]) > np.linalg.norm(p[-1] - g[0]):
            p = p[::-1]  # the same board found from its other end
        shift = ((p - g) * unit).sum(axis=1)
        x = r / corner
        out[name] = float((x * shift).sum() / (x * x).sum())
    return out


def halo(bgr: np.ndarray, ref: ReferenceStripe, colour: str) -> list[float] | None:
    """The laser channel HALO_AT_PX beyond a clipped core's half-maximum edge, as a share of
    the clip level above the band's floor (medians over the clipped lines, both sides), or
    None without 10 clipped lines."""
    ch = LASER_CHANNEL[colour]
    far = BAND_PX + max(HALO_AT_PX)
    prof, centre, at = _bands(bgr, ref, far)
    clipped = np.isfinite(ref.clip_centre[at])
    if clipped.sum() < 10:
        return None
    own = prof[clipped][..., ch]
    floor = np.percentile(own, 5, axis=1)
    share = (own - floor[:, None]) / np.maximum(255.0 - floor[:, None], 1.0)
    half_w = 0.5 * ref.width[at][clipped]
    k = np.arange(own.shape[1])[None, :]
    dist = np.abs(k - centre[clipped][:, None]) - half_w[:, None]
    out = []
    for d in HALO_AT_PX:
        near = np.abs(dist - d) <= 0.5
        out.append(round(float(np.median(share[near])), 3) if near.any() else float("nan"))
    return out
