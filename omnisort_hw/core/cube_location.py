"""Cubes on the floor: colour blobs in the fisheye image -> centre and yaw in S and B.

How:

1. Colour segmentation in HSV with a configurable table (`ColorTable`: a list of H, S, V
   ranges per colour, OpenCV's H in [0, 180)). Pixels that are saturated or dark but match no
   colour of the table form "unknown" blobs, so an object of an unexpected colour is reported
   instead of silently ignored. Connected components, small ones dropped.
2. Each blob is a cube of known size standing upright on the floor (the floor plane comes from
   the robot registration: the plane z = floor_z in B). Seen from the camera centre, the cube's
   silhouette, cut with the plane of its top face, is the convex hull of the top square and
   of the bottom square projected centrally onto that plane (a uniform shrink towards the
   camera's foot point). The blob's sub-pixel outline (midpoints between inside and outside
   pixels, where a 50 % covered pixel flips) is cast onto the top plane, and the centre and
   yaw are fitted so that the outline lies on that hull's boundary (robust least squares,
   residuals weighted to pixels). Outline points next to another blob (occlusion) are left out.
3. Where the laser stripe crosses the cube's side faces (a laser-on image), its points on the
   laser plane lie on the sides of the footprint square; they join the fit with their own,
   much smaller, noise, which pins the faces they touch.
4. The 1-sigma of the centre and yaw comes from the fit's covariance (residual scatter
   propagated through the Jacobian), the outline's points counted as correlated as their
   residuals are round the outline (neighbours share pixels' quantisation).

Everything is array in, array out; the caller supplies the image(s), the camera model and
rotation, T_SB and the floor height.
"""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import ConvexHull, QhullError

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.records import CubeReply, RejectedBlob
from omnisort_hw.core.residual_correlation import correlation_inflation
from omnisort_hw.errors import ConfigError, InputError

UNKNOWN = "unknown"

# H (0-179), S, V ranges per colour; several ranges are OR-ed (red wraps around H = 0).
DEFAULT_COLORS: dict[str, tuple[tuple[int, int, int, int, int, int], ...]] = {
    "red": ((0, 7, 110, 255, 50, 255), (168, 179, 110, 255, 50, 255)),
    "yellow": ((20, 34, 110, 255, 80, 255),),
    "green": ((40, 85, 100, 255, 40, 255),),
    "blue": ((96, 130, 110, 255, 40, 255),),
    "black": ((0, 179, 0, 110, 0, 45),),
}
# A pixel belongs to "some object" when saturated or dark (anything not floor-grey).
FOREGROUND_MIN_SATURATION = 110
FOREGROUND_MIN_VALUE = 50
DARK_MAX_VALUE = 45
LASER_SIGMA_MM = 1.0  # 1-sigma of a laser point across its face (sub-pixel stripe at ~1 m)
LASER_GATE_MM = 6.0  # laser points this close to the fitted footprint's sides are candidates
LASER_AGREE_MM = 1.0  # ... and are used when their median distance to the sides is below this
MIN_LASER_POINTS = 5
PIXEL_SIGMA_FLOOR_PX = 0.15  # the outline is never trusted more than this


@dataclass(frozen=True)
class ColorTable:
    """Named colours, each a tuple of (h_lo, h_hi, s_lo, s_hi, v_lo, v_hi) ranges (OpenCV HSV)."""

    ranges: dict[str, tuple[tuple[int, int, int, int, int, int], ...]]

    @classmethod
    def default(cls) -> ColorTable:
        return cls(dict(DEFAULT_COLORS))

    @classmethod
    def from_mapping(cls, data: Mapping[str, object], source: str = "colours") -> ColorTable:
        """{name: [[h_lo, h_hi, s_lo, s_hi, v_lo, v_hi], ...]} (TOML/JSON), checked."""
        out: dict[str, tuple[tuple[int, int, int, int, int, int], ...]] = {}
        for name, value in data.items():
            key = f"{source}.{name}"
            if name == UNKNOWN:
                raise ConfigError(f"{key}: {UNKNOWN!r} is reserved for unmatched objects")
            rows: Sequence[object] = [value]
            if isinstance(value, list | tuple) and value and isinstance(value[0], list | tuple):
                rows = value
            parsed = []
            for i, row in enumerate(rows):
                row = row if isinstance(row, list | tuple) else [row]
                whole = [v for v in row if isinstance(v, int) and not isinstance(v, bool)]
                if len(row) != 6 or len(whole) != 6:
                    raise ConfigError(f"{key}[{i}]: expected 6 whole numbers, got {row!r}")
                h0, h1, s0, s1, v0, v1 = whole
                if not (0 <= h0 <= h1 <= 179 and 0 <= s0 <= s1 <= 255 and 0 <= v0 <= v1 <= 255):
                    raise ConfigError(
                        f"{key}[{i}]: need 0 <= h_lo <= h_hi <= 179 and 0 <= lo <= hi <= 255 "
                        f"for S and V, got {row!r}"
                    )
                parsed.append((h0, h1, s0, s1, v0, v1))
            out[str(name)] = tuple(parsed)
        if not out:
            raise ConfigError(f"{source}: no colours defined")
        return cls(out)

    @classmethod
    def load(cls, path: str | Path) -> ColorTable:
        """A colour table from a TOML or JSON file (a top-level `colors` table, or the file)."""
        p = Path(path)
        try:
            text = p.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise ConfigError(f"{p}: colour table file not found") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise ConfigError(f"{p}: cannot be read as a colour table ({exc})") from None
        try:
            data = json.loads(text) if p.suffix.lower() == ".json" else tomllib.loads(text)
        except (ValueError, tomllib.TOMLDecodeError) as exc:
            raise ConfigError(f"{p}: not a readable colour table ({exc})") from None
        table = data.get("colors", data) if isinstance(data, dict) else None
        if not isinstance(table, dict):
            raise ConfigError(f"{p}: expected a table of colours ({{name: [h, h, s, s, v, v]}})")
        return cls.from_mapping(table, source=str(p))

    def names(self) -> list[str]:
        return list(self.ranges)

    def masks(self, bgr: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """Per-colour masks (uint8 0/255) and the mask of unmatched saturated/dark pixels."""
        hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
        out: dict[str, np.ndarray] = {}
        matched = np.zeros(bgr.shape[:2], np.uint8)
        for name, rows in self.ranges.items():
            m: np.ndarray = np.zeros(bgr.shape[:2], np.uint8)
            for h0, h1, s0, s1, v0, v1 in rows:
                m |= cv2.inRange(hsv, (h0, s0, v0), (h1, s1, v1))
            m &= ~matched  # the first colour that matches a pixel keeps it
            out[name] = m
            matched |= m
        fg: np.ndarray = cv2.inRange(
            hsv, (0, FOREGROUND_MIN_SATURATION, FOREGROUND_MIN_VALUE), (179, 255, 255)
        )
        fg |= cv2.inRange(hsv, (0, 0, 0), (179, 255, DARK_MAX_VALUE))
        return out, fg & ~matched


# ---- geometry -------------------------------------------------------------------------------


@dataclass(frozen=True)
class FloorGeometry:
    """The floor and the frame the cubes are reported in: T_SB and the floor height in B."""

    T_SB: np.ndarray
    floor_z_B_mm: float = 0.0

    @property
    def normal_S(self) -> np.ndarray:
        return self.T_SB[:3, 2]

    def plane_offset(self, height_mm: float) -> float:
        """k of the plane n . x = k in S at `height_mm` above the floor (n = B's z in S)."""
        n = self.normal_S
        return float(n @ self.T_SB[:3, 3] + self.floor_z_B_mm + height_mm)

    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        """In-plane axes (B's x and y in S)."""
        return self.T_SB[:3, 0], self.T_SB[:3, 1]

    def to_plane(self, rays_S: np.ndarray, height_mm: float) -> tuple[np.ndarray, np.ndarray]:
        """Rays (N, 3) -> 2D coordinates (N, 2) on the plane at `height_mm` (origin: the foot of
        the camera's perpendicular) and whether the ray meets it in front of the camera."""
        k = self.plane_offset(height_mm)
        n = self.normal_S
        denom = rays_S @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = k / denom
        ok = np.isfinite(t) & (t > 0)
        pts = rays_S * np.where(ok, t, np.nan)[:, None]
        e1, e2 = self.axes()
        return np.stack([pts @ e1, pts @ e2], axis=1), ok

    def from_plane(self, xy: np.ndarray, height_mm: float) -> np.ndarray:
        """2D plane coordinates (N, 2) at `height_mm` -> points in S (N, 3)."""
        e1, e2 = self.axes()
        k = self.plane_offset(height_mm)
        xy = np.asarray(xy, float).reshape(-1, 2)
        return k * self.normal_S + xy[:, :1] * e1 + xy[:, 1:] * e2


def _square(c: np.ndarray, theta: float, half: float) -> np.ndarray:
    """Vertices (4, 2) of a square of half side `half` centred at c, turned by theta."""
    ct, st = math.cos(theta), math.sin(theta)
    local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * half
    return local @ np.array([[ct, st], [-st, ct]]) + c


def silhouette(c: np.ndarray, theta: float, half: float, shrink: float) -> np.ndarray:
    """The cube's silhouette on its top plane: hull vertices (M, 2), counter-clockwise."""
    top = _square(c, theta, half)
    pts = np.vstack([top, shrink * top])
    try:
        hull = ConvexHull(pts)
    except QhullError:
        return top
    return pts[hull.vertices]


def _polygon_distance(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Signed distance (outside > 0) of points (N, 2) from a convex CCW polygon's boundary:
    the largest signed distance to its edge lines (exact inside and along the edges)."""
    a = poly
    b = np.roll(poly, -1, axis=0)
    e = b - a
    normal = np.stack([e[:, 1], -e[:, 0]], axis=1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    d = np.einsum("nkj,kj->nk", pts[:, None, :] - a[None], normal)
    return d.max(axis=1)


def outline_points(mask: np.ndarray, others: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel outline of a binary mask: midpoints between 4-neighbouring inside/outside pixel
    centres (N, 2) in (u, v), and whether the outside pixel is free (not in `others`)."""
    m = mask.astype(bool)
    o = others.astype(bool)
    pts, free = [], []
    # Horizontal neighbours.
    diff = m[:, 1:] != m[:, :-1]
    ys, xs = np.nonzero(diff)
    outside_x = np.where(m[ys, xs], xs + 1, xs)
    pts.append(np.stack([xs + 0.5, ys.astype(float)], axis=1))
    free.append(~o[ys, outside_x])
    # Vertical neighbours.
    diff = m[1:, :] != m[:-1, :]
    ys, xs = np.nonzero(diff)
    outside_y = np.where(m[ys, xs], ys + 1, ys)
    pts.append(np.stack([xs.astype(float), ys + 0.5], axis=1))
    free.append(~o[outside_y, xs])
    return np.concatenate(pts), np.concatenate(free)


@dataclass
class Cube:
    """One located cube. Positions in mm, angles in degrees, yaw modulo 90 in (-45, 45]."""

    color: str
    center_S: np.ndarray
    center_B: np.ndarray
    yaw_S_deg: float
    yaw_B_deg: float
    sigma_xy_mm: tuple[float, float]  # 1-sigma along B's x and y
    sigma_yaw_deg: float
    rms_px: float
    area_px: int
    outline_points: int
    laser_points: int
    bbox: tuple[int, int, int, int]  # x, y, w, h in pixels
    notes: list[str] = field(default_factory=list)
    outline_px: np.ndarray | None = field(default=None, repr=False)
    # Covariance (mm^2) of the centre along B's x and y: the outline fit's own, and with the
    # calibration's part added (core.cube_uncertainty), when known.
    fit_cov_xy: np.ndarray | None = field(default=None, repr=False)
    position_cov_xy: np.ndarray | None = field(default=None, repr=False)

    @property
    def sigma_mm(self) -> float:
        """Radial 1-sigma of the centre (mm), every known source."""
        if self.position_cov_xy is not None:
            return float(np.sqrt(max(np.trace(self.position_cov_xy), 0.0)))
        return float(np.hypot(*self.sigma_xy_mm))

    @property
    def position_sigma_xy_mm(self) -> tuple[float, float]:
        """1-sigma along B's x and y, every known source."""
        if self.position_cov_xy is None:
            return self.sigma_xy_mm
        d = np.sqrt(np.clip(np.diag(self.position_cov_xy), 0.0, None))
        return float(d[0]), float(d[1])

    def summary(self) -> CubeReply:
        """The cube as a reply gives it (no pixels: `cell_pictures.cube_pixels` adds them)."""
        return CubeReply(
            color=self.color,
            center_S_mm=np.round(self.center_S, 2).tolist(),
            center_B_mm=np.round(self.center_B, 2).tolist(),
            yaw_S_deg=round(self.yaw_S_deg, 3),
            yaw_B_deg=round(self.yaw_B_deg, 3),
            sigma_mm=round(self.sigma_mm, 3),
            sigma_xy_B_mm=[round(v, 3) for v in self.position_sigma_xy_mm],
            sigma_fit_xy_B_mm=[round(v, 3) for v in self.sigma_xy_mm],
            sigma_yaw_deg=round(self.sigma_yaw_deg, 3),
            rms_px=round(self.rms_px, 3),
            area_px=self.area_px,
            outline_points=self.outline_points,
            laser_points=self.laser_points,
            notes=list(self.notes),
        )


@dataclass(frozen=True)
class LocateSettings:
    """Cube size, the region searched (S, on the floor), blob filters and the floor board."""

    cube_size_mm: float = 100.0
    region_S_mm: tuple[float, float, float, float] | None = None  # xmin, xmax, ymin, ymax
    exclude_S_mm: tuple[tuple[float, float, float, float], ...] = ()
    min_area_fraction: float = 0.35  # of the predicted silhouette area
    max_area_fraction: float = 2.2
    floor_z_B_mm: float = 0.0


def _wrap90(deg: float) -> float:
    """An angle modulo 90 degrees in (-45, 45]."""
    return float(-((-deg + 45.0) % 90.0 - 45.0))


def _predicted_area_px(
    geom: FloorGeometry, model: OcamModel, R_SC: np.ndarray, c: np.ndarray, size: float
) -> float:
    """Image area (px) of the cube's silhouette at plane point c (axis-aligned, yaw 0)."""
    k_top = geom.plane_offset(size)
    k_floor = geom.plane_offset(0.0)
    poly = silhouette(c, 0.0, size / 2.0, k_top / k_floor)
    pts_S = geom.from_plane(poly, size)
    px = model.ray_to_pixel(pts_S @ R_SC)
    return float(cv2.contourArea(px.astype(np.float32)))


def _fit_cube(
    edge_xy: np.ndarray,
    edge_w: np.ndarray,
    laser_xy: np.ndarray,
    half: float,
    shrink: float,
    x0: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Robust fit of (cx, cy, theta): outline on the silhouette, laser points on the footprint
    sides. Returns the parameters, the residuals (px-equivalent) and the Jacobian."""
    lw = 1.0 / LASER_SIGMA_MM

    def residuals(x: np.ndarray) -> np.ndarray:
        c, th = x[:2], x[2]
        poly = silhouette(c, th, half, shrink)
        r_edge = _polygon_distance(poly, edge_xy) * edge_w
        if len(laser_xy) == 0:
            return r_edge
        ct, st = math.cos(th), math.sin(th)
        d = laser_xy - c
        local = np.stack([d[:, 0] * ct + d[:, 1] * st, -d[:, 0] * st + d[:, 1] * ct], axis=1)
        r_las = (np.max(np.abs(local), axis=1) - half) * lw
        return np.concatenate([r_edge, r_las])

    best = None
    for dth in (0.0, math.pi / 4):
        start = x0 + np.array([0.0, 0.0, dth])
        sol = least_squares(residuals, start, loss="soft_l1", f_scale=1.0, x_scale=[10, 10, 0.1])
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None
    return best.x, best.fun, best.jac


def _outline_order(xy: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Indices that walk the outline points (N, 2) round a convex blob: by angle about its
    centre."""
    d = xy - centre
    return np.argsort(np.arctan2(d[:, 1], d[:, 0]), kind="stable")


def blob_verdict(
    centroid_px: np.ndarray,
    area_px: float,
    geom: FloorGeometry,
    model: OcamModel,
    R_SC: np.ndarray,
    st: LocateSettings,
) -> tuple[np.ndarray, str] | None:
    """Whether a colour blob can be a cube: its centroid on the cubes' top plane (xy) and an
    empty reason, or why not (outside the region, in an excluded area, not a cube's area
    there); None when its ray misses the plane."""
    size = st.cube_size_mm
    ray = model.pixel_to_ray(np.asarray(centroid_px, float).reshape(1, 2)) @ R_SC.T
    xy, ok = geom.to_plane(ray, size)
    if not ok[0]:
        return None
    where = geom.from_plane(xy, size)[0]
    if st.region_S_mm is not None:
        x0r, x1r, y0r, y1r = st.region_S_mm
        if not (x0r <= where[0] <= x1r and y0r <= where[1] <= y1r):
            return xy[0], "outside the search region"
    if any(a <= where[0] <= b and c <= where[1] <= d for a, b, c, d in st.exclude_S_mm):
        return xy[0], "in an excluded region"
    expected = _predicted_area_px(geom, model, R_SC, xy[0], size)
    if not st.min_area_fraction * expected <= area_px <= st.max_area_fraction * expected:
        return xy[0], f"area {area_px:.0f} px, a cube there covers ~{expected:.0f} px"
    return xy[0], ""


def locate_cubes(
    image: np.ndarray,
    model: OcamModel,
    R_SC: np.ndarray,
    T_SB: np.ndarray,
    colors: ColorTable | None = None,
    settings: LocateSettings | None = None,
    laser_points_S: np.ndarray | None = None,
) -> tuple[list[Cube], dict[str, Any]]:
    """Cubes in a laser-off colour image (BGR), optionally refined with laser points in S.

    Returns the cubes (known and "unknown" colours) and diagnostics (masks, rejected blobs).
    """
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise InputError(f"image: expected an 8-bit BGR image, got {img.dtype} {img.shape}")
    if (img.shape[1], img.shape[0]) != tuple(model.image_size):
        raise InputError(
            f"image is {img.shape[1]}x{img.shape[0]} but the camera model is for "
            f"{model.image_size[0]}x{model.image_size[1]}"
        )
    colors = colors or ColorTable.default()
    st = settings or LocateSettings()
    geom = FloorGeometry(np.asarray(T_SB, float), st.floor_z_B_mm)
    size = st.cube_size_mm
    k_top, k_floor = geom.plane_offset(size), geom.plane_offset(0.0)
    if not (k_floor < 0 and k_top < 0):
        raise InputError("the floor (from T_SB) must be below the camera for cube location")
    shrink = k_top / k_floor
    masks, unknown = colors.masks(img)
    masks = {**masks, UNKNOWN: unknown}
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
    clean = {k: cv2.morphologyEx(m, cv2.MORPH_OPEN, kernel) for k, m in masks.items()}
    all_fg: np.ndarray = np.zeros(img.shape[:2], np.uint8)
    for m in clean.values():
        all_fg |= m
    laser_xy = np.empty((0, 2))
    if laser_points_S is not None and len(laser_points_S):
        lp = np.asarray(laser_points_S, float)
        lp = lp[np.all(np.isfinite(lp), axis=1)]
        height = lp @ geom.normal_S - k_floor
        lp = lp[(height > 5.0) & (height < size - 5.0)]
        e1, e2 = geom.axes()
        laser_xy = np.stack([lp @ e1, lp @ e2], axis=1)
    cubes: list[Cube] = []
    rejected: list[RejectedBlob] = []
    for name, m in clean.items():
        n, labels, stats, centroids = cv2.connectedComponentsWithStats(m, connectivity=4)
        for i in range(1, n):
            x, y, w, h, area = (int(v) for v in stats[i])
            if area < 30:
                continue
            verdict = blob_verdict(centroids[i], area, geom, model, R_SC, st)
            if verdict is None:
                continue
            xy, reason = verdict
            where = geom.from_plane(xy[None], size)[0]
            at_S = np.round(where, 1).tolist()
            if reason:
                rejected.append(RejectedBlob(name, area, at_S, reason))
                continue
            cube = _locate_one(
                labels[y - 1 : y + h + 1, x - 1 : x + w + 1] == i,
                all_fg[y - 1 : y + h + 1, x - 1 : x + w + 1],
                (x - 1, y - 1),
                name,
                area,
                model,
                R_SC,
                geom,
                size,
                shrink,
                laser_xy,
            )
            if cube is None:
                rejected.append(RejectedBlob(name, area, at_S, "outline fit failed"))
                continue
            cube.bbox = (x, y, w, h)
            cubes.append(cube)
    cubes.sort(key=lambda c: (c.center_S[1], c.center_S[0]))
    return cubes, {"masks": clean, "rejected": rejected}


def _locate_one(
    blob: np.ndarray,
    fg: np.ndarray,
    offset: tuple[int, int],
    color: str,
    area: int,
    model: OcamModel,
    R_SC: np.ndarray,
    geom: FloorGeometry,
    size: float,
    shrink: float,
    laser_xy_all: np.ndarray,
) -> Cube | None:
    """Fit one blob (a boolean crop at `offset`) as a cube; None when its outline is too short
    (mostly hidden by other objects)."""
    half = size / 2.0
    pad = np.pad(blob, 1)
    near_other = cv2.dilate(((fg > 0) & ~blob).astype(np.uint8), np.ones((5, 5), np.uint8))
    others = np.pad(near_other > 0, 1)
    pts, free = outline_points(pad, others)
    pts = pts + np.array(offset, float) - 1.0
    pts = pts[free]
    if len(pts) < 12:
        return None
    rays = model.pixel_to_ray(pts) @ R_SC.T
    xy, ok = geom.to_plane(rays, size)
    xy, pts = xy[ok], pts[ok]
    # Millimetres per pixel on the top plane at each outline point (from a 1 px step).
    step = model.pixel_to_ray(pts + np.array([0.5, 0.5])) @ R_SC.T
    xy2, _ = geom.to_plane(step, size)
    mm_per_px = np.linalg.norm(xy2 - xy, axis=1) / math.sqrt(0.5)
    weight = 1.0 / np.maximum(mm_per_px, 1e-6)
    x0 = np.concatenate([xy.mean(axis=0), [0.0]])
    rect = cv2.minAreaRect(xy.astype(np.float32))
    x0[2] = math.radians(rect[2])
    # Pull the start away from the camera's foot point (the side faces lie towards it).
    radial = x0[:2] / max(np.linalg.norm(x0[:2]), 1e-9)
    x0[:2] += radial * half * (1.0 - shrink)
    near = np.empty((0, 2))
    if len(laser_xy_all):
        d = np.linalg.norm(laser_xy_all - x0[:2], axis=1)
        near = laser_xy_all[d < 2.0 * size]
    params, res, jac = _fit_cube(xy, weight, np.empty((0, 2)), half, shrink, x0)
    laser_xy = np.empty((0, 2))
    notes = []
    if len(near):
        ct, st = math.cos(params[2]), math.sin(params[2])
        d = near - params[:2]
        local = np.stack([d[:, 0] * ct + d[:, 1] * st, -d[:, 0] * st + d[:, 1] * ct], axis=1)
        gap = np.max(np.abs(local), axis=1) - half
        on_face = near[np.abs(gap) < LASER_GATE_MM]
        # The laser refines only when its points agree with the outline fit (a stripe on a
        # surface of its own colour is found poorly and would pull the cube off).
        if len(on_face) >= MIN_LASER_POINTS:
            spread = float(np.median(np.abs(gap[np.abs(gap) < LASER_GATE_MM])))
            if spread <= LASER_AGREE_MM:
                laser_xy = on_face
                params, res, jac = _fit_cube(xy, weight, laser_xy, half, shrink, params)
            else:
                notes.append(f"laser points off the outline fit by {spread:.1f} mm: not used")
    n_edge = len(xy)
    r_edge = res[:n_edge]
    rms_px = float(np.sqrt(np.mean(r_edge**2)))
    scale = max(float(np.median(np.abs(r_edge))) * 1.4826, PIXEL_SIGMA_FLOOR_PX)
    # Neighbouring outline points share their pixels' quantisation and threshold errors: the
    # edge rows count as n / tau independent ones (tau from the residuals' own correlation,
    # walked round the outline).
    tau = correlation_inflation(r_edge[_outline_order(xy, params[:2])])
    jac = jac.copy()
    jac[:n_edge] /= math.sqrt(tau)
    try:
        cov = scale**2 * np.linalg.inv(jac.T @ jac)
    except np.linalg.LinAlgError:
        cov = np.full((3, 3), np.nan)
    c2 = params[:2]
    top_centre = geom.from_plane(c2[None], size)[0]
    centre_S = top_centre - half * geom.normal_S
    T_BS = np.linalg.inv(geom.T_SB)
    centre_B = T_BS[:3, :3] @ centre_S + T_BS[:3, 3]
    yaw_B = _wrap90(math.degrees(params[2]))
    e1 = geom.axes()[0]
    yaw_S = _wrap90(yaw_B + math.degrees(math.atan2(e1[1], e1[0])))
    if rms_px > 1.0:
        notes.append(f"outline fits poorly (rms {rms_px:.2f} px): occluded or not a cube")
    return Cube(
        color=color,
        center_S=centre_S,
        center_B=centre_B,
        yaw_S_deg=yaw_S,
        yaw_B_deg=yaw_B,
        sigma_xy_mm=(float(np.sqrt(cov[0, 0])), float(np.sqrt(cov[1, 1]))),
        sigma_yaw_deg=float(np.degrees(np.sqrt(cov[2, 2]))),
        rms_px=rms_px,
        area_px=area,
        outline_points=n_edge,
        laser_points=len(laser_xy),
        bbox=(0, 0, 0, 0),
        notes=notes,
        outline_px=pts,
        fit_cov_xy=cov[:2, :2],
    )


def match_to_truth(
    cubes: Sequence[Cube], truth_centres_S: np.ndarray, max_mm: float = 60.0
) -> list[int | None]:
    """Index of the nearest true centre (S) for each cube, None beyond `max_mm` (evaluation)."""
    truth = np.asarray(truth_centres_S, float).reshape(-1, 3)
    out: list[int | None] = []
    for c in cubes:
        if len(truth) == 0:
            out.append(None)
            continue
        d = np.linalg.norm(truth[:, :2] - c.center_S[:2], axis=1)
        k = int(np.argmin(d))
        out.append(k if d[k] <= max_mm else None)
    return out
