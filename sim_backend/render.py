"""Fisheye rendering: pybullet cube-map faces remapped through the camera model, with analytic
shading of the patterned planes, the laser stripe from per-sample 3D points, and adaptive
supersampling.

How a frame is made:

1. `FisheyeGeometry` (cached per camera model, R_SC, face size and lens circle): the ray of every
   pixel centre inside the lens circle, in S; which cube-map face each ray falls in; the
   tightest frustum per face (a 185 degree lens needs the front face and the front half of
   four side faces); the faces' places in one atlas image; the atlas coordinate of each ray.
2. pybullet's CPU renderer (`ER_TINY_RENDERER`) draws each face with an explicit view and
   off-centre projection: colour, segmentation (body ids) and depth (linearised, stored as
   inverse distance along the ray so bilinear interpolation is exact on planes).
3. `shade()` takes any set of rays: the atlas gives the body each ray hits; target walls and
   checkerboards are intersected analytically with their plane and shaded from the exact
   point (patterns, markers, borders); the floor is analytic too; other bodies use pybullet's
   colour and depth. The laser intensity comes from the signed distance of the 3D point to the
   laser plane, a Gaussian across the plane, the range fall-off and a shadow test.
4. Pixel centres are shaded first; pixels whose neighbours differ (body, pattern class, colour),
   that carry laser light or straddle the lens circle are re-shaded with k x k sub-samples
   and box-averaged (`render.adaptive = false` supersamples every pixel).

The result keeps the laser light separate from the scene colour, so the "real camera" mode can
make it uneven and speckled before it is composited.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections import OrderedDict
from dataclasses import dataclass, field

import cv2
import numpy as np
import pybullet as p

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.radiometry import srgb_to_linear
from sim_backend.laser import HALL_RADIUS_MM, LaserFan, LaserPlane
from sim_backend.world import MM, AnalyticBox, AnalyticCylinder, Panel, SimWorld

NEAR_M = 0.01
FAR_M = 40.0
GUARD_PX = 3
_REMAP_COLS = 4096
_CHUNK = 400_000

# forward and up of each cube-map face in the camera frame C; right = forward x up.
_FACES: tuple[tuple[str, tuple[float, float, float], tuple[float, float, float]], ...] = (
    ("front", (0.0, 0.0, 1.0), (0.0, -1.0, 0.0)),
    ("+x", (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    ("-x", (-1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    ("+y", (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
    ("-y", (0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
    ("back", (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),
)


def remap_flat(src: np.ndarray, xy: np.ndarray, interpolation: int) -> np.ndarray:
    """cv2.remap for a flat list of sample coordinates (n, 2) -> (n,) or (n, channels).

    OpenCV limits map sides to < 32767, so the list is folded into rows of 4096.
    """
    n = xy.shape[0]
    rows = -(-n // _REMAP_COLS) if n else 0
    pad = rows * _REMAP_COLS - n
    mx = np.pad(xy[:, 0].astype(np.float32, copy=False), (0, pad)).reshape(rows, _REMAP_COLS)
    my = np.pad(xy[:, 1].astype(np.float32, copy=False), (0, pad)).reshape(rows, _REMAP_COLS)
    if n == 0:
        return np.zeros((0, *src.shape[2:]), src.dtype)
    out = cv2.remap(src, mx, my, interpolation, borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(rows * _REMAP_COLS, *src.shape[2:])[:n]


@dataclass(frozen=True)
class FaceSpec:
    """One cube-map face: basis in C, frustum in tangent units, pixel size and atlas row."""

    name: str
    forward: np.ndarray
    right: np.ndarray
    up: np.ndarray
    x0: float
    y0: float
    pitch: float
    width: int
    height: int
    row: int


class FisheyeGeometry:
    """Per-camera-configuration tables: pixel rays, faces, atlas coordinates (built once)."""

    def __init__(
        self, model: OcamModel, R_SC: np.ndarray, face_px: int, circle_fov_deg: float
    ) -> None:
        t0 = time.perf_counter()
        self.model = model
        self.R_SC = np.asarray(R_SC, float)
        self.face_px = int(face_px)
        self.width, self.height = model.image_size
        self.theta_circle = min(np.deg2rad(circle_fov_deg) / 2.0, model.theta_max)
        uu, vv = np.meshgrid(
            np.arange(self.width, dtype=float), np.arange(self.height, dtype=float)
        )
        rays_c = model.pixel_to_ray(np.stack([uu, vv], axis=-1))
        theta = np.arccos(np.clip(rays_c[..., 2], -1.0, 1.0))
        # Angular size of a pixel (for the lens-circle ring that is always supersampled).
        gy, gx = np.gradient(theta)
        px_angle = np.hypot(gx, gy)
        self.domain = theta <= self.theta_circle + 1.5 * px_angle
        self.inside = theta <= self.theta_circle
        self.ring = self.domain & (np.abs(theta - self.theta_circle) <= 0.75 * px_angle)
        self.pixel_index = np.flatnonzero(self.domain).astype(np.int64)
        rays_dom = rays_c.reshape(-1, 3)[self.pixel_index]
        self.rays_S = (rays_dom @ self.R_SC.T).astype(np.float32)
        self.inside_dom = self.inside.reshape(-1)[self.pixel_index]
        self.pixel_angle = float(np.median(px_angle[self.inside]))
        self.faces = self._layout(rays_dom)
        self.atlas_shape = (
            max(f.row + f.height for f in self.faces),
            max(f.width for f in self.faces),
        )
        self.atlas_xy = self.rays_to_atlas(rays_dom)
        self.key = ""
        self.build_seconds = time.perf_counter() - t0

    def _layout(self, rays: np.ndarray) -> list[FaceSpec]:
        """Faces that some ray needs, each with the smallest frustum covering its rays."""
        pitch = 2.0 / self.face_px
        guard = GUARD_PX * pitch
        forwards = np.array([f[1] for f in _FACES])
        owner = np.argmax(rays @ forwards.T, axis=1)
        faces = []
        row = 0
        for k, (name, fwd, up) in enumerate(_FACES):
            sel = rays[owner == k]
            if sel.shape[0] == 0:
                continue
            f, u = np.array(fwd), np.array(up)
            r = np.cross(f, u)
            depth = sel @ f
            x = (sel @ r) / depth
            y = (sel @ u) / depth
            x0 = max(float(x.min()), -1.0) - guard
            x1 = min(float(x.max()), 1.0) + guard
            y0 = max(float(y.min()), -1.0) - guard
            y1 = min(float(y.max()), 1.0) + guard
            width = int(np.ceil((x1 - x0) / pitch))
            height = int(np.ceil((y1 - y0) / pitch))
            faces.append(FaceSpec(name, f, r, u, x0, y0, pitch, width, height, row))
            row += height
        return faces

    def rays_to_atlas(self, rays_c: np.ndarray) -> np.ndarray:
        """Atlas coordinates (n, 2) float32 of rays in C.

        pybullet's TINY renderer samples column c at x0 + c * pitch and image row r at
        y0 + (height - 1 - r) * pitch (its rows run top-down, its samples sit on pixel corners).
        """
        forwards = np.array([f.forward for f in self.faces])
        owner = np.argmax(rays_c @ forwards.T, axis=1)
        out = np.empty((rays_c.shape[0], 2), np.float32)
        for k, f in enumerate(self.faces):
            idx = np.flatnonzero(owner == k)
            if idx.size == 0:
                continue
            sel = rays_c[idx]
            depth = sel @ f.forward
            x = (sel @ f.right) / depth
            y = (sel @ f.up) / depth
            col = (x - f.x0) / f.pitch
            rw = (f.height - 1) - (y - f.y0) / f.pitch
            out[idx, 0] = np.clip(col, 0.0, f.width - 1)
            out[idx, 1] = np.clip(rw, 0.0, f.height - 1) + f.row
        return out

    def subsample(self, pixels: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """k x k sub-sample rays (S), atlas coordinates and in-circle flags of flat pixels."""
        offs = (np.arange(k) + 0.5) / k - 0.5
        ou, ov = np.meshgrid(offs, offs)
        u = (pixels % self.width)[:, None] + ou.ravel()[None, :]
        v = (pixels // self.width)[:, None] + ov.ravel()[None, :]
        rays_c = self.model.pixel_to_ray(np.stack([u.ravel(), v.ravel()], axis=-1))
        inside = rays_c[:, 2] >= np.cos(self.theta_circle)
        return (
            (rays_c @ self.R_SC.T).astype(np.float32),
            self.rays_to_atlas(rays_c),
            inside,
        )


_GEOMETRY_CACHE: OrderedDict[str, FisheyeGeometry] = OrderedDict()
_GEOMETRY_CACHE_SIZE = 2


def geometry_for(
    model: OcamModel, R_SC: np.ndarray, face_px: int, circle_fov_deg: float
) -> FisheyeGeometry:
    """The cached `FisheyeGeometry` for this camera configuration (LRU of two)."""
    key_src = json.dumps(model.to_dict(), sort_keys=True) + np.round(R_SC, 12).tobytes().hex()
    key = hashlib.sha1(f"{key_src}|{face_px}|{circle_fov_deg}".encode()).hexdigest()
    geo = _GEOMETRY_CACHE.get(key)
    if geo is None:
        geo = FisheyeGeometry(model, R_SC, face_px, circle_fov_deg)
        geo.key = key
        _GEOMETRY_CACHE[key] = geo
        while len(_GEOMETRY_CACHE) > _GEOMETRY_CACHE_SIZE:
            _GEOMETRY_CACHE.popitem(last=False)
    else:
        _GEOMETRY_CACHE.move_to_end(key)
    return geo


@dataclass
class Atlas:
    """The rendered cube-map faces in one image: RGB, body ids and inverse ray distance (1/mm)."""

    rgb: np.ndarray
    seg: np.ndarray
    inv_dist: np.ndarray


def _raster_rects(world: SimWorld, geo: FisheyeGeometry) -> list[tuple[int, int, int, int]]:
    """Per face, the pixel rectangle (c0, c1, r0, r1) where a rasterised body can appear.

    Each link's bounding sphere is a cone of directions; 16 points on a polygon around the
    cone's rim (widened so it circumscribes the cone) are projected into the face. A sphere
    reaching behind a face's plane claims the whole face; a face nothing reaches is empty.
    """
    spheres = []
    for body in world.raster_bodies():
        n_links = p.getNumJoints(body, physicsClientId=world.client)
        for link in range(-1, n_links):
            lo, hi = p.getAABB(body, link, physicsClientId=world.client)
            lo, hi = np.asarray(lo) / MM, np.asarray(hi) / MM
            spheres.append(((lo + hi) / 2.0 @ world.R_SC, float(np.linalg.norm(hi - lo)) / 2.0))
    phi = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
    rects = []
    for f in geo.faces:
        box = [np.inf, -np.inf, np.inf, -np.inf]
        full = False
        for centre, radius in spheres:
            depth = float(centre @ f.forward)
            if depth + radius <= 0.0:
                continue
            dist = float(np.linalg.norm(centre))
            if depth - radius <= NEAR_M / MM or dist <= radius * 1.01:
                full = True
                break
            axis = centre / dist
            alpha = np.arctan(np.tan(np.arcsin(radius / dist)) / np.cos(np.pi / 16)) * 1.02
            e1 = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(axis, e1)
            rim = np.cos(alpha) * axis + np.sin(alpha) * (
                np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
            )
            d = rim @ f.forward
            if np.any(d <= 1e-6):
                full = True
                break
            x, y = (rim @ f.right) / d, (rim @ f.up) / d
            box = [
                min(box[0], x.min()),
                max(box[1], x.max()),
                min(box[2], y.min()),
                max(box[3], y.max()),
            ]
        if full:
            rects.append((0, f.width, 0, f.height))
            continue
        if not np.isfinite(box[0]):
            rects.append((0, 0, 0, 0))
            continue
        c0 = int(np.clip(np.floor((box[0] - f.x0) / f.pitch) - 2, 0, f.width))
        c1 = int(np.clip(np.ceil((box[1] - f.x0) / f.pitch) + 3, 0, f.width))
        r0 = int(np.clip(np.floor(f.height - 1 - (box[3] - f.y0) / f.pitch) - 2, 0, f.height))
        r1 = int(np.clip(np.ceil(f.height - 1 - (box[2] - f.y0) / f.pitch) + 3, 0, f.height))
        rects.append((c0, c1, r0, r1))
    return rects


def render_atlas(world: SimWorld, geo: FisheyeGeometry) -> Atlas:
    """Draw the rasterised bodies (arm, cubes) with pybullet's CPU renderer into the atlas.

    The static bodies are shaded exactly from their geometry, so they are made transparent
    for the duration (the CPU renderer then skips them at no cost), and each face is drawn
    only over the rectangle where a rasterised body can appear (an off-centre frustum on the
    face's own pixel grid, so the samples stay where `rays_to_atlas` expects them).
    """
    h, w = geo.atlas_shape
    rgb = np.zeros((h, w, 3), np.uint8)
    seg = np.full((h, w), -1.0, np.float32)
    inv = np.zeros((h, w), np.float32)
    ren = world.scene.render
    light = np.asarray(ren.light_direction, float)
    light = light / np.linalg.norm(light)
    colors = {b.body: b.color for b in world.info.boxes} | {
        c.body: c.color for c in world.info.cylinders
    }
    static = sorted(world.static_bodies())
    for body in static:
        p.changeVisualShape(body, -1, rgbaColor=[*colors[body], 0.0], physicsClientId=world.client)
    try:
        for f, (c0, c1, r0, r1) in zip(geo.faces, _raster_rects(world, geo), strict=True):
            if c1 <= c0 or r1 <= r0:
                continue
            fw, fh = c1 - c0, r1 - r0
            fwd = world.R_SC @ f.forward
            up = world.R_SC @ f.up
            view = p.computeViewMatrix([0.0, 0.0, 0.0], list(fwd), list(up))
            xl = f.x0 + c0 * f.pitch
            yb = f.y0 + (f.height - r1) * f.pitch
            proj = p.computeProjectionMatrix(
                xl * NEAR_M,
                (xl + fw * f.pitch) * NEAR_M,
                yb * NEAR_M,
                (yb + fh * f.pitch) * NEAR_M,
                NEAR_M,
                FAR_M,
            )
            _, _, img, zbuf, ids = p.getCameraImage(
                fw,
                fh,
                view,
                proj,
                renderer=p.ER_TINY_RENDERER,
                lightDirection=list(light * 10.0),
                lightColor=[1.0, 1.0, 1.0],
                lightAmbientCoeff=ren.ambient,
                lightDiffuseCoeff=ren.diffuse,
                lightSpecularCoeff=0.0,
                shadow=0,
                physicsClientId=world.client,
            )
            img = np.asarray(img, np.uint8).reshape(fh, fw, 4)
            zbuf = np.asarray(zbuf, np.float32).reshape(fh, fw)
            ids = np.asarray(ids, np.int32).reshape(fh, fw)
            z_m = FAR_M * NEAR_M / (FAR_M - (FAR_M - NEAR_M) * zbuf)
            xs = xl + np.arange(fw) * f.pitch
            ys = yb + (fh - 1 - np.arange(fh)) * f.pitch
            stretch = np.sqrt(1.0 + xs[None, :] ** 2 + ys[:, None] ** 2)
            dist_mm = z_m * stretch * 1000.0
            hit = ids >= 0
            rows = slice(f.row + r0, f.row + r1)
            cols = slice(c0, c1)
            rgb[rows, cols] = img[..., :3]
            seg[rows, cols] = np.where(hit, ids, -1).astype(np.float32)
            inv[rows, cols] = np.where(hit, 1.0 / dist_mm, 0.0).astype(np.float32)
    finally:
        for body in static:
            p.changeVisualShape(
                body, -1, rgbaColor=[*colors[body], 1.0], physicsClientId=world.client
            )
    return Atlas(rgb, seg, inv)


@dataclass
class Hits:
    """What each ray sees: distance (mm, inf for the hall), colour, class key and body id
    (-1 for the floor and the hall)."""

    t: np.ndarray
    rgb: np.ndarray
    key: np.ndarray
    body: np.ndarray

    def copy(self) -> Hits:
        """An independent copy (the cached static hits must not be edited)."""
        return Hits(self.t.copy(), self.rgb.copy(), self.key.copy(), self.body.copy())

    def take(self, sl: slice) -> Hits:
        """A copy of a slice of the samples."""
        return Hits(
            self.t[sl].copy(), self.rgb[sl].copy(), self.key[sl].copy(), self.body[sl].copy()
        )


@dataclass
class Shaded:
    """Shading of a set of samples: colour (n, 3) RGB in [0, 1], laser intensity, class key."""

    rgb: np.ndarray
    laser: np.ndarray
    key: np.ndarray


@dataclass(frozen=True)
class _BoxTables:
    """Per-frame constants of an analytic box: frame, bounding cone, face shading, pattern."""

    body: int
    R: np.ndarray
    origin_local: np.ndarray
    half: np.ndarray
    axis_dir: np.ndarray
    cos_cone: float
    face_rgb: np.ndarray
    panel: Panel | None
    panel_face: tuple[int, float]


@dataclass(frozen=True)
class _CylTables:
    """Per-frame constants of an analytic cylinder: axis, radius, bounding cone, colour."""

    body: int
    p0: np.ndarray
    axis: np.ndarray
    length: float
    radius: float
    cone_dirs: np.ndarray
    cos_cones: np.ndarray
    color: np.ndarray


class Shader:
    """Shades rays of one frame: exact static geometry, the rasterised rest, the laser.

    The static scene (floor, target walls, boards, bins: boxes that never move) is intersected
    analytically (`static_hits`); for the pixel centres this is done once per camera
    configuration and world and cached. The atlas holds only the moving or non-box bodies; a
    rasterised body wins where it is nearer than the static hit. Cubes are boxes too: the
    raster says where one is seen, the exact ray/box hit gives its colour and distance.
    """

    def __init__(self, world: SimWorld, atlas: Atlas, laser_on: bool) -> None:
        self.world = world
        self.atlas = atlas
        self.laser_on = laser_on
        scene = world.scene
        ren = scene.render
        light = np.asarray(ren.light_direction, float)
        self.light = light / np.linalg.norm(light)
        self.ambient, self.diffuse = ren.ambient, ren.diffuse
        # sRGB scenes: colours (albedo x shading) are encoded values; light is linear
        self.decode = ren.tone_curve == "srgb"
        self.hall = np.asarray(ren.hall_color.rgb, np.float32)
        self.sky = np.asarray(ren.sky_color.rgb, np.float32)
        self.plane = LaserPlane(world.laser_normal, world.laser_distance)
        self.fan = LaserFan.compute(world, self.plane) if laser_on else None
        las = scene.laser
        self.sigma = las.width_mm / (2.0 * np.sqrt(2.0 * np.log(2.0)))
        self.no_laser = np.array(sorted(world.info.no_laser), np.int64)
        boxes = world.analytic_boxes()
        self.static = [self._tables(b) for b in boxes if not b.dynamic]
        self.cylinders = [self._cyl_tables(c) for c in world.info.cylinders]
        self.dynamic = [self._tables(b) for b in boxes if b.dynamic]
        top = max([b.body for b in self.dynamic] + [0])
        self.dynamic_lut = np.full(top + 2, -1, np.int32)
        for k, b in enumerate(self.dynamic):
            self.dynamic_lut[b.body + 1] = k

    def _lambert(self, normal: np.ndarray) -> float:
        return float(self.ambient + self.diffuse * max(0.0, float(normal @ self.light)))

    def _tables(self, box: AnalyticBox) -> _BoxTables:
        R = box.R
        faces = np.empty((6, 3), np.float32)
        for axis in range(3):
            for j, sign in enumerate((1.0, -1.0)):
                faces[2 * axis + j] = np.asarray(box.color) * self._lambert(R[:, axis] * sign)
        dist = float(np.linalg.norm(box.center))
        radius = float(np.linalg.norm(box.half)) + 1.0
        cos_cone = -2.0 if dist <= radius else float(np.cos(np.arcsin(radius / dist)))
        panel = self.world.info.panels.get(box.body)
        panel_face = (-1, 0.0)
        if panel is not None:
            dots = R.T @ panel.rect.normal
            axis = int(np.argmax(np.abs(dots)))
            panel_face = (axis, float(np.sign(dots[axis])))
        return _BoxTables(
            box.body,
            R.astype(np.float32),
            (-R.T @ box.center).astype(np.float32),
            box.half.astype(np.float32),
            (box.center / max(dist, 1e-9)).astype(np.float32),
            cos_cone,
            faces,
            panel,
            panel_face,
        )

    @staticmethod
    def _cyl_tables(c: AnalyticCylinder) -> _CylTables:
        """Tables of a cylinder; its candidate rays come from the bounding cones of pieces of
        at most 100 mm (a long rod's single bounding sphere would hold the camera)."""
        axis = c.p1 - c.p0
        length = float(np.linalg.norm(axis))
        n = max(1, int(np.ceil(length / 100.0)))
        piece = length / n
        centres = c.p0 + (np.arange(n) + 0.5)[:, None] * (axis / n)
        dist = np.linalg.norm(centres, axis=1)
        radius = float(np.hypot(piece / 2.0, c.radius)) + 1.0
        with np.errstate(invalid="ignore"):
            cos = np.where(dist <= radius, -2.0, np.cos(np.arcsin(np.minimum(radius / dist, 1.0))))
        return _CylTables(
            c.body,
            c.p0.astype(np.float64),
            axis / length,
            length,
            c.radius,
            (centres / np.maximum(dist, 1e-9)[:, None]).astype(np.float32),
            cos.astype(np.float32),
            np.asarray(c.color, np.float32),
        )

    @staticmethod
    def _cylinder(c: _CylTables, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Ray/capped-cylinder entry for rays from 0: (hit, distance, outward normal (n, 3))."""
        d = rays.astype(np.float64)
        w = -c.p0
        da = d @ c.axis
        wa = float(w @ c.axis)
        d_perp = d - da[:, None] * c.axis
        w_perp = w - wa * c.axis
        qa = np.einsum("ij,ij->i", d_perp, d_perp)
        qb = d_perp @ w_perp
        qc = float(w_perp @ w_perp) - c.radius**2
        disc = qb * qb - qa * qc
        with np.errstate(invalid="ignore", divide="ignore"):
            t_side = (-qb - np.sqrt(disc)) / qa
        h = wa + t_side * da
        side = (disc >= 0) & (qa > 1e-12) & (t_side > 0) & (h >= 0) & (h <= c.length)
        t = np.where(side, t_side, np.inf)
        normal = np.zeros_like(d)
        pts = t_side[:, None] * d - c.p0
        radial = pts - (pts @ c.axis)[:, None] * c.axis
        normal[side] = radial[side] / c.radius
        for h_cap, sign in ((0.0, -1.0), (c.length, 1.0)):
            with np.errstate(invalid="ignore", divide="ignore"):
                t_cap = (h_cap - wa) / da
            p_cap = t_cap[:, None] * d - c.p0
            r_cap = p_cap - (p_cap @ c.axis)[:, None] * c.axis
            inside = np.einsum("ij,ij->i", r_cap, r_cap) <= c.radius**2
            cap = inside & (t_cap > 0) & (t_cap < t) & (sign * da < 0)
            t = np.where(cap, t_cap, t)
            normal[cap] = sign * c.axis
        hit = np.isfinite(t)
        return hit, t.astype(np.float32), normal

    def _nearest_cylinders(self, rays: np.ndarray, hits: Hits) -> None:
        """Let the static cylinders replace what is behind them."""
        for c in self.cylinders:
            inside = rays @ c.cone_dirs[0] >= c.cos_cones[0]
            for direction, cos in zip(c.cone_dirs[1:], c.cos_cones[1:], strict=True):
                inside |= rays @ direction >= cos
            cand = np.flatnonzero(inside)
            if cand.size == 0:
                continue
            hit, tt, normal = self._cylinder(c, rays[cand])
            closer = hit & (tt < hits.t[cand])
            sel = cand[closer]
            lam = self.ambient + self.diffuse * np.clip(normal[closer] @ self.light, 0.0, None)
            hits.rgb[sel] = c.color[None, :] * lam[:, None].astype(np.float32)
            hits.t[sel] = tt[closer]
            hits.body[sel] = c.body
            along = np.abs(normal[closer] @ c.axis) > 0.5
            hits.key[sel] = c.body * 8 + 4 + along.astype(np.int32)

    @staticmethod
    def _slab(b: _BoxTables, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Ray/box entry: (hit, distance, entry face index 2*axis + (sign < 0)) for rays from 0.

        Written with per-axis columns (no reductions over a short last axis, which numpy does
        slowly): the entry is the largest of the three near-slab distances.
        """
        near, far, dirs = [], None, []
        for axis in range(3):
            d = rays @ b.R[:, axis]
            with np.errstate(divide="ignore", invalid="ignore"):
                inv = np.float32(1.0) / d
                t1 = (-b.half[axis] - b.origin_local[axis]) * inv
                t2 = (b.half[axis] - b.origin_local[axis]) * inv
            near.append(np.minimum(t1, t2))
            hi = np.maximum(t1, t2)
            far = hi if far is None else np.minimum(far, hi)
            dirs.append(d)
        n0, n1, n2 = near
        tmin = np.maximum(np.maximum(n0, n1), n2)
        axis = np.where(tmin == n0, 0, np.where(tmin == n1, 1, 2))
        d_axis = np.where(axis == 0, dirs[0], np.where(axis == 1, dirs[1], dirs[2]))
        hit = (tmin <= far) & (tmin > 0)
        face = 2 * axis + (d_axis > 0)
        return hit, tmin, face

    def _shade_box(
        self,
        b: _BoxTables,
        idx: np.ndarray,
        rays: np.ndarray,
        tt: np.ndarray,
        face: np.ndarray,
        hits: Hits,
    ) -> None:
        """Write colour, key, distance and body of box hits (pattern on the panel face)."""
        hits.rgb[idx] = b.face_rgb[face]
        hits.key[idx] = b.body * 8 + 4 + face // 2
        hits.t[idx] = tt
        hits.body[idx] = b.body
        if b.panel is None:
            return
        axis, sign = b.panel_face
        on = face == 2 * axis + (1 if sign < 0 else 0)
        if not on.any():
            return
        rect = b.panel.rect
        sel = idx[on]
        pts = rays[on].astype(np.float64) * tt[on, None].astype(np.float64)
        a = (pts - rect.origin) @ rect.axis_u
        bb = (pts - rect.origin) @ rect.axis_v
        albedo, cls = b.panel.pattern.shade(a, bb)
        hits.rgb[sel] = albedo * self._lambert(rect.normal)
        hits.key[sel] = b.body * 8 + 1 + cls.astype(np.int32)

    def _nearest_boxes(self, tables: list[_BoxTables], rays: np.ndarray, hits: Hits) -> None:
        """Let every box whose bounding cone holds a ray replace what is behind it."""
        for b in tables:
            cand = np.flatnonzero(rays @ b.axis_dir >= b.cos_cone)
            if cand.size == 0:
                continue
            hit, tt, face = self._slab(b, rays[cand])
            closer = hit & (tt < hits.t[cand])
            sel = cand[closer]
            self._shade_box(b, sel, rays[sel], tt[closer], face[closer], hits)

    def static_hits(self, rays: np.ndarray) -> Hits:
        """Exact hits of rays (n, 3) in S on the static scene: floor, hall and static boxes."""
        rz = rays[:, 2]
        floor = self.world.floor
        down = rz < -1e-6
        with np.errstate(divide="ignore", invalid="ignore"):
            tz = np.where(down, np.float32(floor.z) / rz, np.float32(np.inf))
            x = tz * rays[:, 0]
            y = tz * rays[:, 1]
            on_floor = down & (x * x + y * y < np.float32(HALL_RADIUS_MM**2))
        albedo, cls = floor.shade(x, y)
        lam = np.float32(self._lambert(np.array([0.0, 0.0, 1.0])))
        w = np.clip(rz * np.float32(2.0) + np.float32(0.3), 0.0, 1.0)[:, None]
        hall = self.hall * (1.0 - w) + self.sky * w
        hits = Hits(
            np.where(on_floor, tz, np.float32(np.inf)).astype(np.float32),
            np.where(on_floor[:, None], albedo * lam, hall).astype(np.float32),
            np.where(on_floor, cls.astype(np.int32) - 8, -16).astype(np.int32),
            np.full(rays.shape[0], -1, np.int32),
        )
        self._nearest_boxes(self.static, rays, hits)
        self._nearest_cylinders(rays, hits)
        return hits

    def shade(
        self, rays: np.ndarray, axy: np.ndarray, static: Hits | None = None, exact: bool = False
    ) -> Shaded:
        """Shade rays (n, 3) in S with atlas coordinates `axy` (n, 2).

        `static` are the rays' precomputed static hits (else computed here). With `exact`
        (sub-samples of edge pixels) every cube whose bounding cone holds a ray is tested too,
        so cube silhouettes are exact rather than quantised to the atlas pixels.
        """
        n = rays.shape[0]
        hits = static if static is not None else self.static_hits(rays)
        seg = remap_flat(self.atlas.seg, axy, cv2.INTER_NEAREST).astype(np.int32)
        raster = np.flatnonzero(seg >= 0)
        if raster.size:
            xy = axy[raster]
            lin = remap_flat(self.atlas.inv_dist, xy, cv2.INTER_LINEAR)
            near = remap_flat(self.atlas.inv_dist, xy, cv2.INTER_NEAREST)
            use = np.where(np.abs(lin - near) > 0.02 * near, near, lin)
            with np.errstate(divide="ignore"):
                t_r = np.where(use > 0, 1.0 / use, np.inf).astype(np.float32)
            wins = t_r < hits.t[raster]
            idx, t_r, seg_r = raster[wins], t_r[wins], seg[raster[wins]]
            k = self.dynamic_lut[np.clip(seg_r + 1, 0, self.dynamic_lut.size - 1)]
            k[seg_r + 1 >= self.dynamic_lut.size] = -1
            for j, b in enumerate(self.dynamic):
                sel = idx[k == j]
                if sel.size == 0:
                    continue
                hit, tt, face = self._slab(b, rays[sel])
                self._shade_box(b, sel[hit], rays[sel[hit]], tt[hit], face[hit], hits)
            other = k < 0
            sel = idx[other]
            if sel.size:
                rgb = remap_flat(self.atlas.rgb, axy[sel], cv2.INTER_LINEAR).astype(np.float32)
                hits.rgb[sel] = rgb * np.float32(1.0 / 255.0)
                hits.t[sel] = t_r[other]
                hits.key[sel] = seg_r[other] * 8
                hits.body[sel] = seg_r[other]
        if exact and self.dynamic:
            self._nearest_boxes(self.dynamic, rays, hits)
        laser = np.zeros(n, np.float32)
        if self.laser_on:
            self._laser(rays, hits, laser)
        rgb = srgb_to_linear(hits.rgb) if self.decode else hits.rgb
        return Shaded(rgb, laser, hits.key)

    def _laser(self, rays: np.ndarray, hits: Hits, out: np.ndarray) -> None:
        """Stripe intensity: Gaussian in the signed distance to the plane, fall-off, shadows."""
        assert self.fan is not None
        las = self.world.scene.laser
        with np.errstate(invalid="ignore"):
            s = hits.t * (rays @ self.plane.normal.astype(np.float32)) + np.float32(
                self.plane.offset
            )
        near = np.abs(s) < 5.0 * self.sigma
        if self.no_laser.size:
            near &= ~np.isin(hits.body, self.no_laser)
        idx = np.flatnonzero(near)
        if idx.size == 0:
            return
        s = s[idx]
        pts = rays[idx].astype(np.float64) * hits.t[idx, None].astype(np.float64)
        lit, rng = self.fan.lit(pts)
        falloff = np.minimum(1.0, (las.reference_range_mm / np.maximum(rng, 1.0)) ** las.falloff)
        gauss = np.exp(-0.5 * (s / self.sigma) ** 2)
        out[idx] = (las.intensity * falloff * gauss * lit).astype(np.float32)


@dataclass
class RenderResult:
    """A rendered frame before compositing: scene colour (H, W, 3) RGB in [0, 1] (linear light
    when the scene's tone curve is sRGB), laser light (H, W) and timings/statistics."""

    base: np.ndarray
    laser: np.ndarray
    stats: dict[str, float] = field(default_factory=dict)


def _flag_pixels(
    key: np.ndarray, rgb: np.ndarray, laser: np.ndarray, geo: FisheyeGeometry
) -> np.ndarray:
    """Pixels to supersample: neighbours differ in class or brightness, laser light, lens ring."""
    lum = rgb.reshape(-1, 3) @ np.array([0.3, 0.59, 0.11], np.float32)
    lum = lum.reshape(key.shape)
    flag = np.zeros(key.shape, bool)
    for axis in (0, 1):
        a = (slice(None), slice(1, None)) if axis else (slice(1, None), slice(None))
        b = (slice(None), slice(None, -1)) if axis else (slice(None, -1), slice(None))
        d = (key[a] != key[b]) | (np.abs(lum[a] - lum[b]) > 0.04)
        flag[a] |= d
        flag[b] |= d
    lit = laser > 1e-4
    if lit.any():
        flag |= cv2.dilate(lit.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    flag |= geo.ring
    return flag & geo.domain


def static_hits_for(world: SimWorld, geo: FisheyeGeometry, shader: Shader) -> Hits:
    """The static hits of the pixel centres, cached on the world per camera configuration."""
    cache = world.render_cache
    hits = cache.get(geo.key)
    if hits is None:
        parts = [
            shader.static_hits(geo.rays_S[start : start + _CHUNK])
            for start in range(0, geo.pixel_index.size, _CHUNK)
        ]
        hits = Hits(
            np.concatenate([h.t for h in parts]),
            np.concatenate([h.rgb for h in parts]),
            np.concatenate([h.key for h in parts]),
            np.concatenate([h.body for h in parts]),
        )
        cache.clear()
        cache[geo.key] = hits
    return hits


def render_frame(world: SimWorld, model: OcamModel, laser_on: bool | None = None) -> RenderResult:
    """Render the world's current state through `model` (laser as the switch says, or as given)."""
    scene = world.scene
    t0 = time.perf_counter()
    geo = geometry_for(model, world.R_SC, scene.render.face_px, scene.camera.image_circle_fov_deg)
    on = world.laser_on if laser_on is None else laser_on
    t1 = time.perf_counter()
    atlas = render_atlas(world, geo)
    shader = Shader(world, atlas, on)
    t2 = time.perf_counter()
    static = static_hits_for(world, geo, shader)
    t3 = time.perf_counter()
    h, w = geo.height, geo.width
    npx = h * w
    key = np.full(npx, -32, np.int32)
    rgb = np.zeros((npx, 3), np.float32)
    laser = np.zeros(npx, np.float32)
    for start in range(0, geo.pixel_index.size, _CHUNK):
        sl = slice(start, start + _CHUNK)
        out = shader.shade(geo.rays_S[sl], geo.atlas_xy[sl], static=static.take(sl))
        inside = geo.inside_dom[sl]
        pix = geo.pixel_index[sl]
        rgb[pix] = out.rgb * inside[:, None]
        laser[pix] = out.laser * inside
        key[pix] = np.where(inside, out.key, -32)
    t4 = time.perf_counter()
    k = scene.render.supersampling
    rgb_img = rgb.reshape(h, w, 3)
    laser_img = laser.reshape(h, w)
    n_super = 0
    if k > 1:
        if scene.render.adaptive:
            todo = np.flatnonzero(_flag_pixels(key.reshape(h, w), rgb_img, laser_img, geo))
        else:
            todo = geo.pixel_index
        per_chunk = max(1, _CHUNK // (k * k))
        for start in range(0, todo.size, per_chunk):
            pix = todo[start : start + per_chunk]
            rays, axy, inside = geo.subsample(pix, k)
            out = shader.shade(rays, axy, exact=True)
            rgb[pix] = (out.rgb * inside[:, None]).reshape(pix.size, k * k, 3).mean(axis=1)
            laser[pix] = (out.laser * inside).reshape(pix.size, k * k).mean(axis=1)
        n_super = int(todo.size)
    t5 = time.perf_counter()
    stats = {
        "geometry_s": t1 - t0,
        "raster_s": t2 - t1,
        "static_s": t3 - t2,
        "shade_s": t4 - t3,
        "supersample_s": t5 - t4,
        "supersampled_pixels": float(n_super),
        "atlas_pixels": float(geo.atlas_shape[0] * geo.atlas_shape[1]),
    }
    return RenderResult(rgb_img, laser_img, stats)
