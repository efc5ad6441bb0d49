"""How sure the intrinsic calibration is: projection uncertainty per pixel, cross-validation,
repeated views.

* Projection uncertainty (as mrcal computes it): a pixel's ray, at infinity, is carried into
  every board's frame with that board's fitted rotation and back with a perturbed one, the
  boards' results averaged, and projected with perturbed intrinsics. Linearised, the pixel's
  2x2 covariance is J C J^T with C the fit's full covariance (sigma_px^2 (J^T J)^-1, intrinsics
  and every board pose): the board poses are marginalised, and a shift of the centre that
  the boards' rotations absorb costs nothing, as it should. Reported as the standard deviation
  in the worst direction (mrcal's `worstdirection-stdev`).
* Cross-validation: leave one view out (or, with many views, two disjoint halves), refit the
  intrinsics on the rest, fit the held-out board's pose alone with the intrinsics frozen, and
  pool the held-out corners' residuals: the error a new view will see, beside the in-sample
  RMS (which the fit has lowered by fitting the noise).
* Repeated views: the same picture given twice (byte-identical pixels) or a board that did not
  move between two shots (corners within a fraction of the corner noise) adds no geometry but
  halves its apparent noise; such views are counted once.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.intrinsics import (
    ImagePoints,
    IntrinsicResult,
    _g_full,
    _Problem,
    _project,
    _refit,
    pose_only_rms,
)
from omnisort_hw.core.records import CrossValidation, ProjectionSigma

ANGLES_DEG = (0.0, 45.0, 60.0, 70.0, 80.0)  # where the report states the uncertainty
ANGLE_BAND_DEG = 2.5  # +- around each angle
CV_HALVES_FROM = 24  # views: from this many on, two disjoint halves instead of leave-one-out
SAME_BOARD_PX = 0.05  # corners this close (RMS) in two views: the board did not move


@dataclass
class ProjectionUncertainty:
    """Worst-direction standard deviation (px) of the projection over a grid of pixels."""

    step_px: int
    grid_uv: np.ndarray = field(repr=False)  # (G, 2)
    sigma_px: np.ndarray = field(repr=False)  # (G,)
    angle_deg: np.ndarray = field(repr=False)  # (G,) off the optical axis
    shape: tuple[int, int] = (0, 0)  # rows, cols of the grid
    axis_px: float = float("nan")  # on the optical axis itself

    def at_angles(self, angles: tuple[float, ...] = ANGLES_DEG) -> dict[str, float | None]:
        """Median sigma at each angle off axis (+- ANGLE_BAND_DEG; 0: on the axis)."""
        out: dict[str, float | None] = {}
        for a in angles:
            if a == 0.0:
                out["0"] = round(self.axis_px, 4) if np.isfinite(self.axis_px) else None
                continue
            near = np.abs(self.angle_deg - a) <= ANGLE_BAND_DEG
            ok = near & np.isfinite(self.sigma_px)
            out[f"{a:g}"] = round(float(np.median(self.sigma_px[ok])), 4) if ok.any() else None
        return out

    def record(self) -> ProjectionSigma:
        return ProjectionSigma(
            what="projection standard deviation, worst direction, at infinity (px)",
            board_poses="marginalised",
            median_px_at_angle_deg=self.at_angles(),
            max_px_in_view=round(float(np.nanmax(self.sigma_px)), 4),
        )


def model_uncertainty(result: IntrinsicResult) -> dict[str, Any]:
    """What the model carries of its calibration's covariance (the board poses marginalised:
    the intrinsics' block of the full covariance), for the map's sigmas downstream."""
    n = result.n_intrinsic
    return {
        "parameters": [float(v) for v in result.params[:n]],
        "covariance": result.covariance[:n, :n].tolist(),
        "rho_scale": float(result.rho_scale),
        "poly_degree": int(result.degree),
    }


def perturbed_models(model: OcamModel, k_sigma: float = 1.0) -> list[tuple[OcamModel, OcamModel]]:
    """Pairs of models +-k_sigma along each principal direction of the model's intrinsic
    covariance (none without one): central differences of anything computed with the model
    then give its covariance from the intrinsics. They are for `pixel_to_ray` only: their
    inverse polynomial is the nominal model's (refitting it would cost more than a map)."""
    unc = model.uncertainty
    if not unc:
        return []
    vec = np.asarray(unc["parameters"], float)
    cov = np.asarray(unc["covariance"], float)
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    rho_scale, degree = float(unc["rho_scale"]), int(unc["poly_degree"])
    out = []
    for lam, v in zip(w, V.T, strict=True):
        if lam <= 0:
            continue
        step = k_sigma * np.sqrt(lam) * v
        out.append(tuple(_unprojection(model, vec + s, rho_scale, degree) for s in (step, -step)))
    return out  # type: ignore[return-value]


def _unprojection(model: OcamModel, vec: np.ndarray, rho_scale: float, degree: int) -> OcamModel:
    g = _g_full(vec[4:]) / rho_scale ** np.arange(degree + 1)
    return replace(
        model,
        poly=-g,
        center_uv=(float(vec[0]), float(vec[1])),
        stretch=(float(vec[2]), float(vec[3]), float(vec[3])),
        uncertainty=None,
    )


def model_from_vector(
    vec: np.ndarray, rho_scale: float, size: tuple[int, int], n_poly: int
) -> OcamModel:
    """The OCam model of an intrinsic parameter vector (the fit's own parametrisation)."""
    g = _g_full(vec[4:]) / rho_scale ** np.arange(n_poly + 1)
    return OcamModel.create(-g, (vec[0], vec[1]), (vec[2], vec[3], vec[3]), size)


def _project_vec(
    vec: np.ndarray, pts: np.ndarray, rho0: np.ndarray, rho_scale: float
) -> np.ndarray:
    return _project(
        pts, vec[:2], np.array([vec[2], vec[3], vec[3]]), _g_full(vec[4:]), rho_scale, rho0
    )


def projection_uncertainty(result: IntrinsicResult, step_px: int = 16) -> ProjectionUncertainty:
    """Projection uncertainty over a grid (every `step_px` pixels) of the model's view."""
    model = result.model
    w, h = model.image_size
    us, vs = np.arange(step_px / 2, w, step_px), np.arange(step_px / 2, h, step_px)
    uv = np.stack(np.meshgrid(us, vs), axis=-1).reshape(-1, 2)
    rays = model.pixel_to_ray(uv)
    rays = rays / np.linalg.norm(rays, axis=1, keepdims=True)
    angle = np.degrees(np.arccos(np.clip(rays[:, 2], -1.0, 1.0)))
    sigma = np.full(len(uv), np.nan)
    inside = np.isfinite(angle) & model.in_view(rays)
    sigma[inside] = pixel_sigmas(result, rays[inside])
    axis = float(pixel_sigmas(result, np.array([[0.0, 0.0, 1.0]]))[0])
    return ProjectionUncertainty(step_px, uv, sigma, angle, (len(vs), len(us)), axis)


def pixel_sigmas(result: IntrinsicResult, rays: np.ndarray) -> np.ndarray:
    """Worst-direction projection sigma (px) of unit rays in C (see module docstring)."""
    cov = projection_covariances(result, rays)
    a, b, d = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    big = 0.5 * (a + d) + np.sqrt(0.25 * (a - d) ** 2 + b**2)
    return np.sqrt(np.clip(big, 0.0, None))


def projection_covariances(result: IntrinsicResult, rays: np.ndarray) -> np.ndarray:
    """(G, 2, 2) covariance of the projection of unit rays in C, board poses marginalised."""
    x, n_i, rs = result.params, result.n_intrinsic, result.rho_scale
    vec = x[:n_i]
    n_views = (len(x) - n_i) // 6
    pts = rays * 1000.0
    centre = vec[:2]
    rho0 = np.hypot(*(result.model.ray_to_pixel(rays) - centre).T)
    J = np.zeros((len(rays), 2, len(x)))
    for i in range(n_i):  # central differences: the intrinsics' own effect
        h = 1e-6 * max(abs(vec[i]), 1.0)
        up, dn = vec.copy(), vec.copy()
        up[i] += h
        dn[i] -= h
        J[:, :, i] = (_project_vec(up, pts, rho0, rs) - _project_vec(dn, pts, rho0, rs)) / (2 * h)
    dq_dv = np.zeros((len(rays), 2, 3))
    for a in range(3):
        e = np.zeros(3)
        e[a] = 1e-4
        dq_dv[:, :, a] = (
            _project_vec(vec, (rays + e) * 1000.0, rho0, rs)
            - _project_vec(vec, (rays - e) * 1000.0, rho0, rs)
        ) / 2e-4
    rotvecs = x[n_i:].reshape(n_views, 6)[:, :3]
    R = Rotation.from_rotvec(rotvecs).as_matrix()
    for j in range(3):  # each board's rotation: the ray through the averaged boards moves
        h = 1e-6
        dr = rotvecs.copy()
        dr[:, j] += h
        D = (Rotation.from_rotvec(dr).as_matrix() @ np.transpose(R, (0, 2, 1)) - np.eye(3)) / h
        dv = np.einsum("kab,gb->gka", D, rays) / n_views  # (G, views, 3)
        cols = n_i + 6 * np.arange(n_views) + j
        J[:, :, cols] = np.einsum("gca,gka->gck", dq_dv, dv)
    return np.einsum("gcp,pq,gdq->gcd", J, result.covariance, J)


def uncertainty_top(unc: ProjectionUncertainty, within_deg: float | None = None) -> float:
    """The colour scale's top (px): the 99th percentile of the sigmas inside `within_deg` off
    the axis (the image circle; all when None), so the few cells beyond the circle, where the
    polynomial is extrapolated and the sigma explodes, do not paint the circle one colour."""
    ok = np.isfinite(unc.sigma_px)
    if within_deg is not None:
        inside = ok & (unc.angle_deg <= within_deg)
        ok = inside if inside.any() else ok
    return float(np.percentile(unc.sigma_px[ok], 99)) if ok.any() else 1.0


def uncertainty_png(
    unc: ProjectionUncertainty, limit_px: float | None = None, within_deg: float | None = None
) -> np.ndarray:
    """The uncertainty map as a BGR picture (one cell per grid point, scaled up), colour from
    0 (blue) to `limit_px` (red; default: `uncertainty_top` within `within_deg`; beyond it,
    red), black outside the view."""
    import cv2

    from omnisort_hw.core.overlays import put_text

    grid = unc.sigma_px.reshape(unc.shape)
    finite = np.isfinite(grid)
    top = limit_px or uncertainty_top(unc, within_deg)
    scaled = np.clip(np.nan_to_num(grid / max(top, 1e-9)) * 255, 0, 255).astype(np.uint8)
    img = cv2.applyColorMap(scaled, cv2.COLORMAP_JET)
    img[~finite] = 0
    img = cv2.resize(img, None, fx=unc.step_px, fy=unc.step_px, interpolation=cv2.INTER_NEAREST)
    legend = f"projection sigma, worst direction: blue 0 .. red {top:.3f} px and more"
    put_text(img, legend, (8, 20))
    for i, (a, s) in enumerate(unc.at_angles().items()):
        if s is not None:
            put_text(img, f"{a} deg: {s:.3f} px", (8, 40 + 18 * i), scale=0.45)
    return img


# ---- cross-validation -------------------------------------------------------------------


def result_views(result: IntrinsicResult, board_points: np.ndarray) -> list[ImagePoints]:
    """The views the fit used, as it used them (corners kept, board points by corner id)."""
    return [
        ImagePoints(
            n, result.corners_px[n], board_points[result.corner_ids[n]], result.corner_ids[n]
        )
        for n in result.images_used
    ]


def cross_validate(result: IntrinsicResult, board_points: np.ndarray) -> CrossValidation:
    """Held-out reprojection error (pooled RMS over the held-out corners, px): leave one view
    out, or two disjoint halves (alternate views) from CV_HALVES_FROM views on."""
    views = result_views(result, board_points)
    names = [v.name for v in views]
    if len(views) >= CV_HALVES_FROM:
        folds = [list(range(0, len(views), 2)), list(range(1, len(views), 2))]
        scheme = "two disjoint halves (alternate views)"
    else:
        folds = [[k] for k in range(len(views))]
        scheme = "leave one view out"
    if len(views) - max(len(f) for f in folds) < 3:
        return CrossValidation("none: fewer than 4 views", None)
    degree = result.degree
    prob = _Problem.build(views, degree, result.rho_scale, result.params[:2])
    sq, count, per_view = 0.0, 0, {}
    for fold in folds:
        train = [v for k, v in enumerate(views) if k not in fold]
        x, p, _ = _refit(train, names, result.params, prob)
        model = model_from_vector(x[: p.n_intr], p.rho_scale, result.model.image_size, degree)
        for k in fold:
            rms = pose_only_rms(model, views[k], result.poses[views[k].name])
            per_view[views[k].name] = round(rms, 4)
            sq += rms**2 * len(views[k].pixels)
            count += len(views[k].pixels)
    return CrossValidation(
        scheme,
        round(float(np.sqrt(sq / count)), 4),
        in_sample_rms_px=round(result.rms_px, 4),
        per_view_rms_px=per_view,
    )


# ---- repeated views ---------------------------------------------------------------------


def pixel_digest(image: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(image).tobytes()).hexdigest()


def unique_images(
    images: list[tuple[str, np.ndarray]],
) -> tuple[list[tuple[str, np.ndarray]], list[dict[str, str]]]:
    """The images without byte-identical repeats (pixels compared), and the repeats found."""
    seen: dict[str, str] = {}
    keep, repeats = [], []
    for name, img in images:
        key = pixel_digest(img)
        if key in seen:
            repeats.append({"file": name, "same_as": seen[key], "how": "identical pixels"})
            continue
        seen[key] = name
        keep.append((name, img))
    return keep, repeats


def same_board_views(result: IntrinsicResult) -> list[dict[str, str]]:
    """Views whose board did not move: the same corners within SAME_BOARD_PX RMS of another
    used view (a fraction of the corner noise; any re-placed board moves pixels, not
    hundredths of one)."""
    names = result.images_used
    out = []
    for i, a in enumerate(names):
        for b in names[:i]:
            ia, ib = result.corner_ids[a], result.corner_ids[b]
            common, ka, kb = np.intersect1d(ia, ib, return_indices=True)
            if len(common) < 0.9 * max(len(ia), len(ib)):
                continue
            diff = result.corners_px[a][ka] - result.corners_px[b][kb]
            if np.sqrt(np.mean(np.sum(diff**2, axis=1))) <= SAME_BOARD_PX:
                out.append({"file": a, "same_as": b, "how": "the same board corners"})
                break
    return out
