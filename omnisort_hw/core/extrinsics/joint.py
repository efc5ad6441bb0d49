"""`joint`: camera rotation and laser plane from one image of the two-sided target.

1. Closed-form start. Each wall's border is a straight 3D line, so its rays span a plane through
   the viewpoint; the two planes meet along the common wall direction Y. The A-D and B-C
   segments (markers at equal positions along the walls) are perpendicular to the walls, which
   gives X. With the rotation, the border planes place the walls (known separation D sets the
   scale) and the laser rays, cut with the wall planes, give 3D points to fit the laser plane.
2. One robust least-squares refinement of all unknowns together: camera roll/pitch/yaw, laser
   roll/pitch/distance, and the nuisance geometry (left wall X, border height, the markers'
   positions along the walls and heights). Residuals are angles between observed rays and the
   model's lines/points, scaled to pixels by the lens' local scale, so every observation is
   weighted by the image noise it carries, and by how many independent measurements its line
   points really are (neighbours share pixels: the inflation is measured from the residuals'
   correlation along the line). The covariance of the solution gives each parameter's standard
   deviation.
3. The same refinement runs on the three-sided target (`ThreeSidedProblem`), started from
   method1's closed form, with the far wall's border and laser line in place of the markers.

Observability: pitch (about Y, the wall direction) is fixed only through the A-D / B-C
markers and the equal height of the borders; its standard deviation is reported as measured.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.covariance import fit_covariance
from omnisort_hw.core.extrinsics.system_calibration import (
    PARAMETERS,
    SystemCalibration,
    fit_laser_plane,
    pixel_scale,
    place_side_walls,
)
from omnisort_hw.core.features import TargetFeatures
from omnisort_hw.core.frames import (
    camera_angles,
    camera_rotation,
    great_circle_normal,
    laser_angles,
    laser_normal,
    nearest_rotation,
    rays_to_plane,
    tangent_basis,
)
from omnisort_hw.errors import CalibrationError

SIDES = ("left", "right")
BORDER_MARKERS = ("border_near", "border_far")
FLOOR_MARKERS = ("floor_near", "floor_far")


@dataclass
class _Obs:
    """Observed rays in C with their pixel scales, per wall."""

    border: dict[str, np.ndarray]
    floor: dict[str, np.ndarray]
    laser: dict[str, np.ndarray]
    markers: dict[tuple[str, str], np.ndarray]
    scale_border: dict[str, np.ndarray]
    scale_floor: dict[str, np.ndarray]
    scale_laser: dict[str, np.ndarray]
    scale_markers: dict[tuple[str, str], float]


def observations(features: TargetFeatures, model: OcamModel) -> _Obs:
    """Rays of every extracted feature of the two side walls."""
    border, floor, laser, markers = {}, {}, {}, {}
    sb, sf, sl, sm = {}, {}, {}, {}
    for side in SIDES:
        if side not in features.walls:
            raise CalibrationError(f"target features have no {side} wall")
        wall = features.walls[side]
        if len(wall.border_px) < 5 or len(wall.laser_px) < 5:
            raise CalibrationError(
                f"{side} wall: {len(wall.border_px)} border and {len(wall.laser_px)} laser points; "
                "at least 5 of each are needed"
            )
        border[side] = model.pixel_to_ray(wall.border_px)
        floor[side] = model.pixel_to_ray(np.asarray(wall.floor_px, float).reshape(-1, 2))
        sf[side] = pixel_scale(model, floor[side])
        laser[side] = model.pixel_to_ray(wall.laser_px)
        sb[side] = pixel_scale(model, border[side])
        sl[side] = pixel_scale(model, laser[side])
        for name in (*BORDER_MARKERS, *FLOOR_MARKERS):
            if name not in wall.markers_px:
                raise CalibrationError(f"{side} wall: marker {name} missing")
            ray = model.pixel_to_ray(np.asarray(wall.markers_px[name], float)[None, :])[0]
            markers[(side, name)] = ray
            sm[(side, name)] = float(pixel_scale(model, ray[None, :])[0])
    if min(len(floor[s]) for s in SIDES) < 5:
        floor = {s: np.zeros((0, 3)) for s in SIDES}
        sf = {s: np.zeros(0) for s in SIDES}
    return _Obs(border, floor, laser, markers, sb, sf, sl, sm)


def _ad_direction(a: np.ndarray, d: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Direction from A to D (rays a, d) given that A - D is perpendicular to y."""
    v = d - (d @ y) / (a @ y) * a
    return v / np.linalg.norm(v)


def closed_form(obs: _Obs, separation: float) -> dict[str, Any]:
    """Initial estimate of all unknowns from the target's geometry (no iteration)."""
    m = {s: great_circle_normal(obs.border[s]) for s in SIDES}
    y = np.cross(m["left"], m["right"])
    y /= np.linalg.norm(y)
    along = obs.markers[("left", "border_far")] - obs.markers[("left", "border_near")]
    if y @ along < 0:
        y = -y
    xs = [
        _ad_direction(obs.markers[("left", n)], obs.markers[("right", n)], y)
        for n in (*BORDER_MARKERS, *FLOOR_MARKERS)
    ]
    x = np.mean(xs, axis=0)
    x -= (x @ y) * y
    x /= np.linalg.norm(x)
    R = nearest_rotation(np.stack([x, y, np.cross(x, y)]))
    # Border plane normal in S is parallel to (-z_b, 0, x_w): z_b / x_w = -m_x / m_z.
    x_left, z_b = place_side_walls(R, m["left"], m["right"], separation)
    walls = {"left": x_left, "right": x_left + separation}
    pts = np.concatenate(
        [rays_to_plane(obs.laser[s] @ R.T, np.array([1.0, 0.0, 0.0]), walls[s]) for s in SIDES]
    )
    n, d, _ = fit_laser_plane(pts)
    marker_pts = {
        key: rays_to_plane((R @ ray)[None, :], np.array([1.0, 0.0, 0.0]), walls[key[0]])[0]
        for key, ray in obs.markers.items()
    }
    y_near = np.mean([p[1] for (s, nm), p in marker_pts.items() if nm.endswith("near")])
    y_far = np.mean([p[1] for (s, nm), p in marker_pts.items() if nm.endswith("far")])
    z_top = np.mean([p[2] for (s, nm), p in marker_pts.items() if nm.startswith("border")])
    z_floor = np.mean([p[2] for (s, nm), p in marker_pts.items() if nm.startswith("floor")])
    roll, pitch, yaw = camera_angles(R)
    l_roll, l_pitch = laser_angles(n)
    x0 = [roll, pitch, yaw, l_roll, l_pitch, d, x_left, z_b, y_near, y_far, z_top, z_floor]
    if len(obs.floor["left"]):
        # The wall/floor line: its plane normal in S is ~ (-z_f, 0, x_w), as for the border.
        mf = R @ great_circle_normal(obs.floor["left"])
        x0.append(-mf[0] / mf[2] * x_left)
    return {
        "x": np.array(x0),
        "R": R,
        "normal": n,
        "d": d,
    }


NAMES = (
    "cam_roll",
    "cam_pitch",
    "cam_yaw",
    "laser_roll",
    "laser_pitch",
    "laser_distance",
    "wall_left_x",
    "border_z",
    "marker_near_y",
    "marker_far_y",
    "marker_top_z",
    "marker_floor_z",
    "floor_z",
)  # floor_z only when the wall/floor lines were extracted


def _order_along(rays: np.ndarray) -> np.ndarray:
    """Indices that sort rays lying near one great circle along it."""
    m = great_circle_normal(rays)
    e1 = rays.mean(axis=0)
    e1 -= (e1 @ m) * m
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(m, e1)
    return np.argsort(np.arctan2(rays @ e2, rays @ e1))


def correlation_inflation(residuals: np.ndarray, max_lag: int = 10) -> float:
    """Variance inflation 1 + 2 sum(rho_k) of an average of residuals ordered along a line,
    from their autocorrelation up to the first lag within the noise of an estimate from n
    points (2 / sqrt(n)); 1 for independent points, about the number of points sharing each
    pixel otherwise."""
    r = np.asarray(residuals, float) - np.mean(residuals)
    n = r.size
    denom = float(r @ r)
    if n < 8 or denom <= 0:
        return 1.0
    total = 0.0
    for k in range(1, min(max_lag, n // 4) + 1):
        rho = float(r[:-k] @ r[k:]) / denom
        if rho <= 2.0 / np.sqrt(n):  # indistinguishable from no correlation
            break
        total += rho
    return float(np.clip(1.0 + 2.0 * total, 1.0, 10.0))


def line_inflation(blocks: dict[str, np.ndarray], rays: dict[str, np.ndarray]) -> dict[str, float]:
    """Per kind of line observation, the point-weighted mean of its lines' inflations."""
    acc: dict[str, list[tuple[float, int]]] = {}
    for name, ray in rays.items():
        if len(ray) == 0:
            continue
        f = correlation_inflation(blocks[name][_order_along(ray)])
        acc.setdefault(name.split("_")[0], []).append((f, len(ray)))
    return {k: sum(f * n for f, n in v) / sum(n for _, n in v) for k, v in acc.items()}


# Block name -> (the dict holding its rays, the dict holding their pixel scales, its key).
LineStore = dict[str, tuple[dict[str, np.ndarray], dict[str, np.ndarray], str]]


class _WeightedProblem:
    """What both targets' problems share: residual blocks named "<kind>_<line>", each kind
    weighted by its measured noise and correlation, stray line points dropped. Subclasses give
    `residual_blocks(p)` and `line_store()` (block name -> (rays dict, scales dict, key))."""

    weights: dict[str, float]
    inflation: dict[str, float]

    def residual_blocks(self, p: np.ndarray) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def line_store(self) -> LineStore:
        raise NotImplementedError

    def line_rays(self) -> dict[str, np.ndarray]:
        """The observed rays behind each line block of `residual_blocks` (for their order)."""
        return {name: rays[key] for name, (rays, _, key) in self.line_store().items()}

    def residuals(self, p: np.ndarray) -> np.ndarray:
        """Weighted residuals: each kind divided by its noise, so the sum is the likelihood."""
        return np.concatenate(
            [
                block * self.weights[name.split("_")[0]]
                for name, block in self.residual_blocks(p).items()
            ]
        )

    def noise_px(self, p: np.ndarray) -> dict[str, float]:
        """Robust noise estimate (px) of each kind of observation at parameters p: 1.4826 MAD
        for the line points, RMS for the few marker coordinates; floored at 0.02 px."""
        kinds: dict[str, list[np.ndarray]] = {}
        for name, block in self.residual_blocks(p).items():
            kinds.setdefault(name.split("_")[0], []).append(block)
        out = {}
        for kind, blocks in kinds.items():
            r = np.concatenate(blocks)
            sigma = np.sqrt(np.mean(r**2)) if kind == "markers" else 1.4826 * np.median(np.abs(r))
            out[kind] = max(float(sigma), 0.02)
        return out

    def estimate_weights(self, p: np.ndarray) -> dict[str, float]:
        """Weight each kind by 1 / (noise * sqrt(inflation)): neighbouring line points share
        pixels (overlapping fit windows, blur), so N of them carry less than N independent
        measurements; the inflation is measured from the residuals' correlation along each
        line, which keeps the kinds' relative weights and the covariance honest."""
        noise = self.noise_px(p)
        self.inflation = line_inflation(self.residual_blocks(p), self.line_rays())
        self.weights.update(
            {k: 1.0 / (v * np.sqrt(self.inflation.get(k, 1.0))) for k, v in noise.items()}
        )
        return noise

    def reject_outliers(self, p: np.ndarray, k: float = 4.0) -> int:
        """Drop line points further than k noise sigmas of their kind from the fit (stray
        extracted points), keeping at least 5 a line; markers are kept (each one is needed)."""
        noise = self.noise_px(p)
        blocks = self.residual_blocks(p)
        dropped = 0
        for name, (rays, scale, key) in self.line_store().items():
            keep = np.abs(blocks[name]) <= k * noise[name.split("_")[0]]
            if not keep.all() and keep.sum() >= 5:
                rays[key], scale[key] = rays[key][keep], scale[key][keep]
                dropped += int((~keep).sum())
        return dropped


class JointProblem(_WeightedProblem):
    """Residuals (pixels) of all observations for a parameter vector (see NAMES)."""

    def __init__(self, obs: _Obs, separation: float) -> None:
        self.obs = obs
        self.separation = separation
        self.has_floor = len(obs.floor["left"]) > 0
        # Per kind of observation, 1 / its noise in pixels (estimate_weights sets them).
        self.weights = {"border": 1.0, "floor": 1.0, "laser": 1.0, "markers": 1.0}
        self.inflation: dict[str, float] = {}
        self.marker_keys = sorted(obs.markers)
        self.marker_rays = np.array([obs.markers[k] for k in self.marker_keys])
        # Which parameter gives each marker's X (wall), Y (near/far) and Z (top/floor).
        self.marker_right = np.array([side == "right" for side, _ in self.marker_keys])
        self.marker_far = np.array([name.endswith("far") for _, name in self.marker_keys])
        self.marker_top = np.array([name.startswith("border") for _, name in self.marker_keys])
        self.marker_basis = tangent_basis(self.marker_rays)
        self.marker_scale = np.array([obs.scale_markers[k] for k in self.marker_keys])

    def split(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, dict[str, float]]:
        R = camera_rotation(p[0], p[1], p[2])
        n = laser_normal(p[3], p[4])
        geom = {
            "left": p[6],
            "right": p[6] + self.separation,
            "z_b": p[7],
            "y_near": p[8],
            "y_far": p[9],
            "z_top": p[10],
            "z_floor": p[11],
        }
        if len(p) > 12:
            geom["z_f"] = p[12]
        return R, n, float(p[5]), geom

    def residual_blocks(self, p: np.ndarray) -> dict[str, np.ndarray]:
        R, n, d, g = self.split(p)
        # Great-circle normals in S of every line, one row each, per side: the border
        # (X = xw, Z = z_b, along Y: normal ~ (-z_b, 0, xw)), the wall/floor line likewise, and
        # the laser line where the wall plane X = xw meets n.(p - (0, 0, -d)) = 0.
        xs = np.array([g["left"], g["right"]])
        z_laser = -d - n[0] * xs / n[2]
        u = np.array([0.0, -n[2], n[1]])
        p0 = np.stack([xs, np.zeros(2), z_laser], axis=1)
        rows = [np.stack([-np.full(2, g["z_b"]), np.zeros(2), xs], axis=1)]
        if self.has_floor:
            rows.append(np.stack([-np.full(2, g["z_f"]), np.zeros(2), xs], axis=1))
        rows.append(np.cross(p0, u))
        normals = np.concatenate(rows)
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        in_C = normals @ R  # rows: R^T m, the normals in the camera frame
        k = len(rows)
        out: dict[str, np.ndarray] = {}
        for i, s in enumerate(SIDES):
            out[f"border_{s}"] = (self.obs.border[s] @ in_C[i]) * self.obs.scale_border[s]
            if self.has_floor:
                out[f"floor_{s}"] = (self.obs.floor[s] @ in_C[2 + i]) * self.obs.scale_floor[s]
            out[f"laser_{s}"] = (self.obs.laser[s] @ in_C[2 * (k - 1) + i]) * self.obs.scale_laser[
                s
            ]
        pts = np.stack(
            [
                np.where(self.marker_right, g["right"], g["left"]),
                np.where(self.marker_far, g["y_far"], g["y_near"]),
                np.where(self.marker_top, g["z_top"], g["z_floor"]),
            ],
            axis=1,
        )
        dirs = pts @ R  # rows: R^T p
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        out["markers"] = (
            np.einsum("nkj,nj->nk", self.marker_basis, dirs) * self.marker_scale[:, None]
        ).ravel()
        return out

    def line_store(self) -> LineStore:
        """Border, laser (and wall/floor) rays and scales of each side, by block name."""
        o = self.obs
        out = {}
        for side in SIDES:
            out[f"border_{side}"] = (o.border, o.scale_border, side)
            out[f"laser_{side}"] = (o.laser, o.scale_laser, side)
            if self.has_floor:
                out[f"floor_{side}"] = (o.floor, o.scale_floor, side)
        return out


def _solve(obs: _Obs, separation_mm: float) -> tuple[Any, JointProblem, dict[str, float]]:
    """LM from the closed-form start; then each kind of observation is weighted by its own
    noise (degraded laser points are noisier than border edges), points beyond 4 sigmas of
    their kind are dropped, and the weighted solve repeated: the maximum-likelihood fit, whose
    covariance gives the standard deviations."""
    start = closed_form(obs, separation_mm)
    prob = JointProblem(obs, separation_mm)
    sol, noise = _refine(prob, start["x"])
    return sol, prob, noise


def _refine(prob: _WeightedProblem, x0: np.ndarray) -> tuple[Any, dict[str, float]]:
    """LM from x0, then twice: drop points beyond 4 sigmas of their kind, weight each kind by
    its measured noise and correlation, solve again. Returns the solution and the noise."""
    sol = least_squares(prob.residuals, x0, method="lm", x_scale="jac", max_nfev=400)
    noise: dict[str, float] = {}
    for _ in range(2):
        prob.reject_outliers(sol.x)
        noise = prob.estimate_weights(sol.x)
        sol = least_squares(prob.residuals, sol.x, method="lm", x_scale="jac", max_nfev=400)
    return sol, noise


def _outcome(
    prob: _WeightedProblem, sol: Any, noise: dict[str, float]
) -> tuple[np.ndarray, dict[str, Any], dict[str, float]]:
    """What both targets report of a refinement: every parameter's standard deviation, the
    residual summary, and the std record of the parameters they share (degrees, mm). The
    residuals are weighted by their measured noise and correlation, so the covariance of the
    maximum-likelihood fit is (J^T J)^-1 without rescaling."""
    std = np.sqrt(np.clip(np.diag(np.linalg.pinv(sol.jac.T @ sol.jac)), 0.0, None))
    blocks = prob.residual_blocks(sol.x)
    residuals = {
        "rms_px": float(np.sqrt(np.mean(np.concatenate(list(blocks.values())) ** 2))),
        **{f"{k}_rms_px": float(np.sqrt(np.mean(v**2))) for k, v in blocks.items()},
        "noise_px": noise,
        "correlation_inflation": dict(prob.inflation),
        "observations": int(sol.fun.size),
    }
    record = {
        **{PARAMETERS[i]: float(np.degrees(std[i])) for i in range(5)},
        PARAMETERS[5]: float(std[5]),
        "border_z_mm": float(std[7]),
        "wall_left_x_mm": float(std[6]),
    }
    return std, residuals, record


def _without_floor(obs: _Obs) -> _Obs:
    return _Obs(
        border=dict(obs.border),
        floor={s: np.zeros((0, 3)) for s in SIDES},
        laser=dict(obs.laser),
        markers=dict(obs.markers),
        scale_border=dict(obs.scale_border),
        scale_floor={s: np.zeros(0) for s in SIDES},
        scale_laser=dict(obs.scale_laser),
        scale_markers=dict(obs.scale_markers),
    )


def calibrate_joint(
    features: TargetFeatures, model: OcamModel, separation_mm: float
) -> SystemCalibration:
    """The default method: closed-form start, then one robust joint refinement (on the
    three-sided target too, where it refines method1's closed form on all three walls).

    The wall/floor lines, when extracted, are used only if they agree with the markers: both
    constrain the walls' cross-section, and a target whose white face meets the floor off its
    own plane on one side (a plinth, an uneven floor) would otherwise bias the pitch by about
    0.07 degree per millimetre. The fit without them is compared with the fit with them on the
    markers' residuals.
    """
    if features.kind == "three-sided":
        return _calibrate_three_sided(features, model, separation_mm)
    t0 = time.perf_counter()
    obs = observations(features, model)
    floor_note = "not extracted"
    sol, prob, noise = _solve(_without_floor(obs), separation_mm)
    if len(obs.floor["left"]):
        markers_alone = float(np.sqrt(np.mean(prob.residual_blocks(sol.x)["markers"] ** 2)))
        sol_f, prob_f, noise_f = _solve(obs, separation_mm)
        markers_with = float(np.sqrt(np.mean(prob_f.residual_blocks(sol_f.x)["markers"] ** 2)))
        # Consistent lines leave the markers' fit as it was (ratio <= 1.04 on every simulated
        # image, clean or degraded); a 1.5 mm asymmetric offset of one line already exceeds
        # 1.25 and would bias pitch by ~0.1 deg.
        if markers_with <= 1.25 * markers_alone + 0.02:
            sol, prob, noise = sol_f, prob_f, noise_f
            floor_note = "used"
        else:
            floor_note = (
                f"not used: with them the markers fit to {markers_with:.2f} px instead of "
                f"{markers_alone:.2f} px (the white face does not meet the floor in its plane)"
            )
    p = sol.x
    _, residuals, calib_std = _outcome(prob, sol, noise)
    R, n, d, geom = prob.split(p)
    calib = SystemCalibration(
        model=model,
        R_SC=R,
        laser_normal=n,
        laser_distance_mm=d,
        method="joint",
        target={
            "kind": features.kind,
            "separation_mm": separation_mm,
            "wall_left_x_mm": float(geom["left"]),
            "wall_right_x_mm": float(geom["right"]),
            "border_z_mm": float(geom["z_b"]),
        },
        residuals={**residuals, "floor_lines": floor_note},
        std=calib_std,
        covariance=fit_covariance(prob, sol, model).to_json(),
    )
    calib.elapsed_s = time.perf_counter() - t0
    return calib


WALLS3 = ("left", "right", "far")


class ThreeSidedProblem(_WeightedProblem):
    """`joint` on the three-sided target: residuals (pixels) of the three borders and the
    three laser lines for (camera roll/pitch/yaw, laser roll/pitch/distance, left wall X,
    border height, far wall Y). The far wall (along X at Y = y_far) supplies what the markers
    supply on the two-sided target, so markers are not needed (both marker layouts work)."""

    def __init__(
        self,
        border: dict[str, np.ndarray],
        laser: dict[str, np.ndarray],
        model: OcamModel,
        separation: float,
    ) -> None:
        self.border = dict(border)
        self.laser = dict(laser)
        self.scale_border = {w: pixel_scale(model, r) for w, r in border.items()}
        self.scale_laser = {w: pixel_scale(model, r) for w, r in laser.items()}
        self.separation = separation
        self.weights = {"border": 1.0, "laser": 1.0}
        self.inflation: dict[str, float] = {}

    def normals_S(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Great-circle normals in S of the borders and laser lines, rows in WALLS3 order."""
        n = laser_normal(p[3], p[4])
        d, x_left, z_b, y_far = p[5], p[6], p[7], p[8]
        xs = np.array([x_left, x_left + self.separation])
        border = np.array([[-z_b, 0.0, xs[0]], [-z_b, 0.0, xs[1]], [0.0, z_b, -y_far]])
        # Side walls X = x: the laser line runs along u = (0, -n_z, n_y) through (x, 0, z).
        z_side = -d - n[0] * xs / n[2]
        side = np.cross(np.stack([xs, np.zeros(2), z_side], axis=1), np.array([0.0, -n[2], n[1]]))
        # Far wall Y = y_far: along u = (-n_z, 0, n_x) through (0, y_far, z).
        far = np.cross(
            np.array([0.0, y_far, -d - n[1] * y_far / n[2]]), np.array([-n[2], 0.0, n[0]])
        )
        laser = np.vstack([side, far])
        border /= np.linalg.norm(border, axis=1, keepdims=True)
        laser /= np.linalg.norm(laser, axis=1, keepdims=True)
        return border, laser

    def residual_blocks(self, p: np.ndarray) -> dict[str, np.ndarray]:
        """Signed distances (px) of every border and laser point from its model line."""
        R = camera_rotation(p[0], p[1], p[2])
        border, laser = (m @ R for m in self.normals_S(p))
        out = {}
        for i, w in enumerate(WALLS3):
            out[f"border_{w}"] = (self.border[w] @ border[i]) * self.scale_border[w]
            out[f"laser_{w}"] = (self.laser[w] @ laser[i]) * self.scale_laser[w]
        return out

    def line_store(self) -> LineStore:
        """Border and laser rays and scales of each wall, by block name."""
        out = {}
        for w in WALLS3:
            out[f"border_{w}"] = (self.border, self.scale_border, w)
            out[f"laser_{w}"] = (self.laser, self.scale_laser, w)
        return out


def _calibrate_three_sided(
    features: TargetFeatures, model: OcamModel, separation_mm: float
) -> SystemCalibration:
    """`joint` for the three-sided target: method1's closed form, then the robust weighted
    refinement of all unknowns on the three walls' borders and laser lines."""
    from omnisort_hw.core.extrinsics.method1 import calibrate_method1

    t0 = time.perf_counter()
    start = calibrate_method1(features, model, separation_mm)
    roll, pitch, yaw = camera_angles(start.R_SC)
    l_roll, l_pitch = laser_angles(start.laser_normal)
    x0 = np.array(
        [
            roll,
            pitch,
            yaw,
            l_roll,
            l_pitch,
            start.laser_distance_mm,
            start.target["wall_left_x_mm"],
            start.target["border_z_mm"],
            start.target["far_wall_y_mm"],
        ]
    )
    border = {w: model.pixel_to_ray(features.walls[w].border_px) for w in WALLS3}
    laser = {w: model.pixel_to_ray(features.walls[w].laser_px) for w in WALLS3}
    prob = ThreeSidedProblem(border, laser, model, separation_mm)
    sol, noise = _refine(prob, x0)
    p = sol.x
    std, residuals, calib_std = _outcome(prob, sol, noise)
    calib = SystemCalibration(
        model=model,
        R_SC=camera_rotation(p[0], p[1], p[2]),
        laser_normal=laser_normal(p[3], p[4]),
        laser_distance_mm=float(p[5]),
        method="joint",
        target={
            "kind": features.kind,
            "separation_mm": separation_mm,
            "wall_left_x_mm": float(p[6]),
            "wall_right_x_mm": float(p[6] + separation_mm),
            "far_wall_y_mm": float(p[8]),
            "border_z_mm": float(p[7]),
        },
        residuals=residuals,
        std={**calib_std, "far_wall_y_mm": float(std[8])},
        covariance=fit_covariance(prob, sol, model).to_json(),
    )
    calib.elapsed_s = time.perf_counter() - t0
    return calib
