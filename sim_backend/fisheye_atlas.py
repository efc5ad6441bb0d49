"""Fisheye camera geometry and the cube-map atlas the renderer looks rays up in.

1. `FisheyeGeometry` (cached per camera model, R_SC, face size and lens circle): the ray of every
   pixel centre inside the lens circle, in S; which cube-map face each ray falls in; the
   tightest frustum per face (a 185 degree lens needs the front face and the front half of
   four side faces); the faces' places in one atlas image; the atlas coordinate of each ray.
2. pybullet's CPU renderer (`ER_TINY_RENDERER`) draws each face with an explicit view and
   off-centre projection: colour, segmentation (body ids) and depth (linearised, stored as
   inverse distance along the ray so bilinear interpolation is exact on planes).

Separate from the shading (`shading.py`) and the frame loop (`render.py`): this is the only
part that asks pybullet for pixels, and its tables depend on the camera, not on the frame.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections import OrderedDict
from dataclasses import dataclass

import cv2
import numpy as np
import pybullet as p

from omnisort_hw.core.camera_model import OcamModel
from sim_backend.world import MM, SimWorld

NEAR_M = 0.01
FAR_M = 40.0
GUARD_PX = 3
_REMAP_COLS = 4096

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
