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
3. The same refinement runs on the three-sided target (`joint_three_sided`), started from
   method1's closed form, with the far wall's border and laser line in place of the markers.

Observability: pitch (about Y, the wall direction) is fixed only through the A-D / B-C
markers and the equal height of the borders; its standard deviation is reported as measured.

With a target description (`core.target_layout`) the markers stand at their measured places
(the unknowns of the markers reduce to the walls' near end Y0), each marker's blob centroid is
compared with the centroid of its rectangle's image, and the right border's height above the
left one is an unknown too (`edge_step`): a border is a printed or textured edge whose imaged
height differs between the walls by about a millimetre on the authors' renders (texture
filtering; the geometry has one height), which through the equal-height assumption alone
tilted pitch by 0.04 degree and laser pitch by 0.09. The borders then give the walls'
direction, and the measured markers (and the wall/floor lines, geometric edges) their tilt.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import OptimizeResult

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.covariance import fit_covariance
from omnisort_hw.core.extrinsics.joint_three_sided import calibrate_three_sided
from omnisort_hw.core.extrinsics.joint_weighted import (
    LineStore,
    _outcome,
    _refine,
    _WeightedProblem,
)
from omnisort_hw.core.extrinsics.system_calibration import (
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
from omnisort_hw.core.target_layout import TargetLayout, image_centroid_shift, side_marker_centres
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


@dataclass(frozen=True)
class ClosedForm:
    """The closed-form start of the joint fit: every unknown (`JointProblem`'s vector), and
    the camera rotation, laser plane normal and distance it was made from."""

    x: np.ndarray
    R: np.ndarray
    normal: np.ndarray
    d: float


def closed_form(obs: _Obs, separation: float, layout: TargetLayout | None = None) -> ClosedForm:
    """Initial estimate of all unknowns from the target's geometry (no iteration); with a
    measured `layout` the marker unknowns are the walls' near end Y0 alone (JointProblem)."""
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
    if layout is not None:
        keys = sorted(marker_pts)
        along = layout.marker_offsets(keys)[:, 0]
        x0 = [*x0[:8], float(np.mean([marker_pts[k][1] for k in keys] - along)), 0.0]
    if len(obs.floor["left"]):
        # The wall/floor line: its plane normal in S is ~ (-z_f, 0, x_w), as for the border.
        mf = R @ great_circle_normal(obs.floor["left"])
        x0.append(-mf[0] / mf[2] * x_left)
    return ClosedForm(np.array(x0), R, n, float(d))


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


class JointProblem(_WeightedProblem):
    """Residuals (pixels) of all observations for a parameter vector (see NAMES)."""

    def __init__(self, obs: _Obs, separation: float, layout: TargetLayout | None = None) -> None:
        self.obs = obs
        self.separation = separation
        self.layout = layout
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
        # With a measured layout: each marker's (along, height above the left border) and the
        # right border's height above the left one; the unknowns are then the left wall's X,
        # the left border's Z and the walls' near end Y0 (see target_layout).
        self.marker_offsets = layout.marker_offsets(self.marker_keys) if layout else None
        self.border_step = layout.border_offset_mm("right") if layout else 0.0

    def split(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, dict[str, float]]:
        R = camera_rotation(p[0], p[1], p[2])
        n = laser_normal(p[3], p[4])
        if self.layout is not None:
            geom = {"left": p[6], "right": p[6] + self.separation, "z_b": p[7], "y0": p[8]}
            geom["edge_step"] = p[9]
            if len(p) > 10:
                geom["z_f"] = p[10]
            return R, n, float(p[5]), geom
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
        z_border = g["z_b"] + np.array([0.0, self.border_step + g.get("edge_step", 0.0)])
        rows = [np.stack([-z_border, np.zeros(2), xs], axis=1)]
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
        dirs = self.marker_centres(g) @ R  # rows: R^T p
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        out["markers"] = (
            np.einsum("nkj,nj->nk", self.marker_basis, dirs) * self.marker_scale[:, None]
        ).ravel()
        return out

    def marker_centres(self, g: dict[str, float]) -> np.ndarray:
        """(K, 3) marker centres in S, in `marker_keys` order, for the geometry `g`."""
        if self.marker_offsets is not None:
            return side_marker_centres(self.marker_keys, self.marker_offsets, g, g["y0"], g["z_b"])
        return np.stack(
            [
                np.where(self.marker_right, g["right"], g["left"]),
                np.where(self.marker_far, g["y_far"], g["y_near"]),
                np.where(self.marker_top, g["z_top"], g["z_floor"]),
            ],
            axis=1,
        )

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


def _solve(
    obs: _Obs,
    separation_mm: float,
    layout: TargetLayout | None = None,
    model: OcamModel | None = None,
) -> tuple[OptimizeResult, JointProblem, dict[str, float]]:
    """LM from the closed-form start; then each kind of observation is weighted by its own
    noise (degraded laser points are noisier than border edges), points beyond 4 sigmas of
    their kind are dropped, and the weighted solve repeated: the maximum-likelihood fit, whose
    covariance gives the standard deviations.

    With a layout that gives the markers' sizes, a marker's blob centroid is compared with the
    centroid of its rectangle's image rather than with the image of its centre: the shift
    (up to half a pixel for 50 mm markers at 1 m) is computed at the solution's pose and the
    solve repeated until it moves no marker by more than 0.005 px."""
    start = closed_form(obs, separation_mm, layout)
    prob = JointProblem(obs, separation_mm, layout)
    sol, noise = _refine(prob, start.x)
    sizes = layout.marker_sizes(prob.marker_keys) if layout is not None else None
    if sizes is None or model is None:
        return sol, prob, noise
    observed = model.ray_to_pixel(prob.marker_rays)
    shift = np.zeros_like(observed)
    for _ in range(3):
        R, _, _, g = prob.split(sol.x)
        new = image_centroid_shift(model, R, prob.marker_centres(g), sizes)
        if np.max(np.abs(new - shift)) < 0.005:
            break
        shift = new
        rays = model.pixel_to_ray(observed - shift)
        moved = _Obs(**{**obs.__dict__, "markers": dict(zip(prob.marker_keys, rays, strict=True))})
        prob = JointProblem(moved, separation_mm, layout)
        sol, noise = _refine(prob, sol.x)
    return sol, prob, noise


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
    features: TargetFeatures,
    model: OcamModel,
    separation_mm: float,
    layout: TargetLayout | None = None,
) -> SystemCalibration:
    """The default method: closed-form start, then one robust joint refinement (on the
    three-sided target too, where it refines method1's closed form on all three walls).

    The wall/floor lines, when extracted, are used only if they agree with the markers: both
    constrain the walls' cross-section, and a target whose white face meets the floor off its
    own plane on one side (a plinth, an uneven floor) would otherwise bias the pitch by about
    0.07 degree per millimetre. The fit without them is compared with the fit with them on the
    markers' residuals.

    `layout`: the target as measured (markers' positions and sizes, border heights); without
    it the symmetric paper target is assumed. Its separation is the one used.
    """
    if layout is not None:
        separation_mm = layout.separation_mm
    if features.kind == "three-sided":
        return calibrate_three_sided(features, model, separation_mm, layout)
    t0 = time.perf_counter()
    obs = observations(features, model)
    floor_note = "not extracted"
    sol, prob, noise = _solve(_without_floor(obs), separation_mm, layout, model)
    if len(obs.floor["left"]):
        markers_alone = float(np.sqrt(np.mean(prob.residual_blocks(sol.x)["markers"] ** 2)))
        sol_f, prob_f, noise_f = _solve(obs, separation_mm, layout, model)
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
            **({"floor_z_mm": float(geom["z_f"])} if "z_f" in geom else {}),
        },
        residuals={**residuals, "floor_lines": floor_note},
        std=calib_std,
        covariance=fit_covariance(prob, sol, model).to_json(),
    )
    calib.elapsed_s = time.perf_counter() - t0
    return calib
