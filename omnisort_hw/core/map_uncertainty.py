"""Every laser map point's uncertainty in millimetres.

A map point is its pixel's ray (camera model, R_SC) cut with the laser plane (n, d). Its 3x3
covariance in S adds, linearised:
* the stripe's pixel noise, measured on the stripe itself: per chain of stripe points, the
  scatter of each point about the chords through its neighbours, over the chain and in a
  window around the point (`stripe_pixel_sigma`),
  applied perpendicular to the stripe in the image (along it a centre only slides along
  its line);
* the extrinsics' covariance from the one-image fit (system.json's `covariance.noise`);
* the intrinsics' covariance (the model's `uncertainty`), one principal mode at a time: the
  pixel re-unprojected through the perturbed model AND the extrinsics shifted by what that
  mode does to their fit (`covariance.intrinsics_modes`), so what the extrinsics absorb of an
  intrinsic error cancels as it does in the real system.

Reported per point: the standard deviation along the surface's normal within the laser plane
(the surface's direction is the local direction of the mapped line; what an obstacle's
distance depends on), along the line, and off the laser plane.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.covariance import ExtrinsicCovariance
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.frames import camera_rotation, laser_normal
from omnisort_hw.core.intrinsics_uncertainty import perturbed_models
from omnisort_hw.core.records import PointSigmaReply

MIN_CHAIN_POINTS = 8  # a chain needs this many points for its own noise estimate
SPACINGS = (1, 2, 4, 8)  # points between a centre and the chord's ends
LOCAL_POINTS = 17  # window of the per-point scatter: 8 points either side
NOISE_FLOOR_PX = 0.01  # below this a measured scatter is the quantisation of the fit, not noise


@dataclass
class PointSigmas:
    """Per map point: covariance in S (N, 3, 3) and the standard deviations (mm) along the
    surface normal (in the laser plane), along the line, off the plane; the pixel noise used."""

    cov_S: np.ndarray = field(repr=False)
    normal_mm: np.ndarray = field(repr=False)
    along_mm: np.ndarray = field(repr=False)
    off_plane_mm: np.ndarray = field(repr=False)
    pixel_sigma_px: np.ndarray = field(repr=False)
    normal_S: np.ndarray = field(repr=False)  # (N, 3) unit surface normals used
    sources: list[str] = field(default_factory=list)

    def summary(self) -> PointSigmaReply:
        ok = np.isfinite(self.normal_mm)
        if not ok.any():
            return PointSigmaReply(list(self.sources))
        return PointSigmaReply(
            list(self.sources),
            normal_mm_median=round(float(np.median(self.normal_mm[ok])), 3),
            normal_mm_max=round(float(np.max(self.normal_mm[ok])), 3),
            pixel_sigma_px_median=round(float(np.median(self.pixel_sigma_px[ok])), 4),
        )


def stripe_pixel_sigma(pixels: np.ndarray, chains: np.ndarray | None) -> np.ndarray:
    """(N,) pixel noise perpendicular to the stripe, per point (see module docstring).

    Per chain, the scatter of its centres about the chords through their neighbours SPACINGS
    points away: the centres' errors are correlated along the stripe (a sub-pixel estimator's
    bias follows the sub-pixel phase as the stripe crosses the pixel grid; an albedo edge
    under the band pulls a few centres one way), which the nearest neighbours hardly see, so
    the spacings are all used. Two scales: the chain's robust scatter (MAD, the largest over
    the spacings; chains too short for their own get the pooled one) and, per point, the RMS
    scatter in a window of LOCAL_POINTS around it (averaged over the spacings: a window's
    estimate is noisy, and the largest of four noisy ones would be biased up), where a
    structured error stands out of a clean chain; each point gets the larger."""
    n = len(pixels)
    chains = np.zeros(n, int) if chains is None else np.asarray(chains, int)
    dists: dict[int, list[np.ndarray]] = {}
    local = np.zeros(n)
    for c in np.unique(chains):
        idx = np.flatnonzero(chains == c)
        if len(idx) < 3:
            continue
        p = pixels[idx]
        centred = p - p.mean(axis=0)
        axis = np.linalg.svd(centred, full_matrices=False)[2][0]
        order = np.argsort(centred @ axis)
        q = p[order]
        chords = [(k, _chord_distances(q, k)) for k in SPACINGS if len(q) > 2 * k]
        dists[int(c)] = [d for _, d in chords]
        if len(q) >= LOCAL_POINTS:
            var = np.mean([_local_rms(d, k, len(q)) ** 2 for k, d in chords], axis=0)
            local[idx[order]] = np.sqrt(var)
    pooled_d = [np.concatenate(v) for v in zip(*[d for d in dists.values() if d], strict=False)]
    pooled = max((_robust_sigma(d) for d in pooled_d if len(d) >= 3), default=NOISE_FLOOR_PX)
    out = np.full(n, pooled)
    for c, per_k in dists.items():
        own = [_robust_sigma(d) for d in per_k if len(d) >= MIN_CHAIN_POINTS]
        if own:
            out[chains == c] = max(own)
    return np.maximum(np.maximum(out, local), NOISE_FLOOR_PX)


def _local_rms(d: np.ndarray, k: int, n: int) -> np.ndarray:
    """(n,) per point of a sorted chain: the scatter of the chord distances `d` (of points
    k..n-k-1) in a window of LOCAL_POINTS about it, less the window's mean (a curve's sagitta),
    as one point's sigma; the chain's ends take their nearest window."""
    w = min(LOCAL_POINTS, len(d))
    c1 = np.concatenate([[0.0], np.cumsum(d)])
    c2 = np.concatenate([[0.0], np.cumsum(d * d)])
    lo = np.clip(np.arange(n) - k - w // 2, 0, len(d) - w)
    mean = (c1[lo + w] - c1[lo]) / w
    var = np.maximum((c2[lo + w] - c2[lo]) / w - mean**2, 0.0)
    return np.sqrt(var / 1.5)


def _chord_distances(q: np.ndarray, k: int) -> np.ndarray:
    """Distance of each point from the chord through the points k before and after it."""
    a, m, b = q[: -2 * k], q[k:-k], q[2 * k :]
    ab = b - a
    length = np.linalg.norm(ab, axis=1)
    ok = length > 1e-9
    cross = ab[:, 0] * (m - a)[:, 1] - ab[:, 1] * (m - a)[:, 0]
    return np.where(ok, cross / np.where(ok, length, 1.0), 0.0)


def _robust_sigma(d: np.ndarray) -> float:
    """1.4826 MAD about the median (a curve's sagitta is the median's), per point: a chord
    distance has 1.5 times one point's variance."""
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(1.5))


def _intersect(rays_C: np.ndarray, R: np.ndarray, n: np.ndarray, d: float) -> np.ndarray:
    rays = rays_C @ R.T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (-d * n[2]) / (rays @ n)
    return rays * np.where(t > 0, t, np.nan)[:, None]


def _geometry(params: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    return camera_rotation(*params[:3]), laser_normal(params[3], params[4]), float(params[5])


def _parameters(calib: SystemCalibration) -> np.ndarray:
    p = calib.parameters()
    return np.array(
        [
            *np.radians([p["cam_roll_deg"], p["cam_pitch_deg"], p["cam_yaw_deg"]]),
            *np.radians([p["laser_roll_deg"], p["laser_pitch_deg"]]),
            p["laser_distance_mm"],
        ]
    )


@lru_cache(maxsize=8)
def _modes_of(model: OcamModel) -> list[tuple[OcamModel, OcamModel]]:
    return perturbed_models(model)


def surface_normals(
    points_S: np.ndarray, calib: SystemCalibration, max_gap_mm: float
) -> np.ndarray:
    """(N, 3) unit normal of the mapped surface at each point, in the laser plane: perpendicular
    to the direction to its neighbours around the emitter (as `mapping.segments` orders them);
    a point without a near neighbour gets the range direction (a face square to the ray)."""
    n = calib.laser_normal
    rel = points_S - np.array([0.0, 0.0, -calib.laser_distance_mm])
    x_l = np.array([1.0, 0.0, 0.0]) - n[0] * n
    x_l /= np.linalg.norm(x_l)
    y_l = np.cross(n, x_l)
    L = np.stack([rel @ x_l, rel @ y_l], axis=1)
    finite = np.all(np.isfinite(L), axis=1)
    out = np.full((len(L), 3), np.nan)
    if finite.sum() == 0:
        return out
    idx = np.flatnonzero(finite)
    Lf = L[idx]
    order = np.argsort(np.arctan2(Lf[:, 1], Lf[:, 0]))
    q = Lf[order]
    nxt, prv = np.roll(q, -1, axis=0), np.roll(q, 1, axis=0)
    near_n = np.linalg.norm(nxt - q, axis=1) <= max_gap_mm
    near_p = np.linalg.norm(q - prv, axis=1) <= max_gap_mm
    tangent = np.where(near_n[:, None], nxt, q) - np.where(near_p[:, None], prv, q)
    length = np.linalg.norm(tangent, axis=1)
    radial = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-9)
    t = np.where(
        length[:, None] > 1e-9,
        tangent / np.maximum(length, 1e-12)[:, None],
        radial[:, ::-1] * [-1.0, 1.0],
    )
    normal_L = np.stack([-t[:, 1], t[:, 0]], axis=1)
    normal_S = normal_L[:, :1] * x_l + normal_L[:, 1:] * y_l
    res = np.empty_like(normal_S)
    res[order] = normal_S
    out[idx] = res
    return out


def point_sigmas(
    pixels: np.ndarray,
    calib: SystemCalibration,
    pixel_sigma_px: np.ndarray,
    points_S: np.ndarray | None = None,
    max_gap_mm: float = 25.0,
) -> PointSigmas:
    """Every point's covariance and standard deviations (see module docstring). `pixel_sigma_px`
    (N,) is the stripe's noise perpendicular to it (`stripe_pixel_sigma`)."""
    pixels = np.asarray(pixels, float).reshape(-1, 2)
    model = calib.model
    rays = model.pixel_to_ray(pixels)
    p0 = _parameters(calib)
    R, n, d = _geometry(p0)
    base = _intersect(rays, R, n, d) if points_S is None else points_S
    sources = ["stripe pixel noise"]
    # Pixel noise, perpendicular to the stripe: the image direction of the surface normal.
    normals = surface_normals(base, calib, max_gap_mm)
    h = 0.25
    ray_u = model.pixel_to_ray(pixels + np.array([h, 0.0]))
    ray_v = model.pixel_to_ray(pixels + np.array([0.0, h]))
    Ju = (_intersect(ray_u, R, n, d) - base) / h
    Jv = (_intersect(ray_v, R, n, d) - base) / h
    # The stripe runs where the point moves along the line: its image direction is the
    # pixel step whose 3D move is along the line; noise acts across it.
    along = np.cross(n, normals)
    A = np.stack([Ju, Jv], axis=2)  # (N, 3, 2) d point / d pixel
    AtA = np.einsum("nki,nkj->nij", A, A)
    Atb = np.einsum("nki,nk->ni", A, along)
    pinv_img = np.stack(  # (A^T A)^-1 A^T along, the 2x2 inverse written out
        [
            AtA[:, 1, 1] * Atb[:, 0] - AtA[:, 0, 1] * Atb[:, 1],
            AtA[:, 0, 0] * Atb[:, 1] - AtA[:, 1, 0] * Atb[:, 0],
        ],
        axis=1,
    )
    pinv_img /= np.maximum(np.linalg.norm(pinv_img, axis=1, keepdims=True), 1e-12)
    across = np.stack([-pinv_img[:, 1], pinv_img[:, 0]], axis=1)
    g = np.einsum("nij,nj->ni", A, across) * pixel_sigma_px[:, None]
    cov = np.einsum("ni,nj->nij", g, g)
    if calib.covariance:
        ext = ExtrinsicCovariance.from_json(calib.covariance)
        sources.append("extrinsics (one-image fit)")
        w, V = np.linalg.eigh(0.5 * (ext.noise + ext.noise.T))
        for lam, v in zip(w, V.T, strict=True):
            if lam <= 0:
                continue
            s = np.sqrt(lam) * v
            plus = _intersect(rays, *_geometry(p0 + s))
            minus = _intersect(rays, *_geometry(p0 - s))
            dp = 0.5 * (plus - minus)
            cov += np.einsum("ni,nj->nij", dp, dp)
        pairs = _modes_of(model)
        if pairs and len(ext.modes) == len(pairs):
            sources.append("intrinsics (camera.json covariance)")
            for (m_plus, m_minus), shift in zip(pairs, ext.modes, strict=True):
                plus = _intersect(m_plus.pixel_to_ray(pixels), *_geometry(p0 + shift))
                minus = _intersect(m_minus.pixel_to_ray(pixels), *_geometry(p0 - shift))
                dp = 0.5 * (plus - minus)
                cov += np.einsum("ni,nj->nij", dp, dp)
    off = np.sqrt(np.clip(np.einsum("i,nij,j->n", n, cov, n), 0.0, None))
    s_normal = np.sqrt(np.clip(np.einsum("ni,nij,nj->n", normals, cov, normals), 0.0, None))
    s_along = np.sqrt(np.clip(np.einsum("ni,nij,nj->n", along, cov, along), 0.0, None))
    return PointSigmas(
        cov, s_normal, s_along, off, np.asarray(pixel_sigma_px, float), normals, sources
    )


def sigma_colours(sigma_mm: np.ndarray) -> np.ndarray:
    """(N, 3) RGB colours of sigmas: blue 0 to red at their 95th percentile (the viewer's)."""
    import cv2

    sig = np.asarray(sigma_mm, float)
    if not np.isfinite(sig).any():
        return np.zeros((len(sig), 3), np.uint8)
    hi = float(np.nanpercentile(sig, 95)) or 1.0
    level = np.clip(np.nan_to_num(sig / hi) * 255, 0, 255).astype(np.uint8)
    return cv2.applyColorMap(level.reshape(-1, 1), cv2.COLORMAP_JET).reshape(-1, 3)[:, ::-1]
