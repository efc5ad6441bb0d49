"""Fisheye rendering of the simulated cell: one frame, adaptively supersampled.

How a frame is made:

1. The camera's `FisheyeGeometry` (pixel rays, cube-map faces) and the pybullet-rendered atlas
   of the faces: `fisheye_atlas.py`.
2. The pixel centres' rays are shaded (`shading.py`: analytic static geometry, the rasterised
   rest, the laser light).
3. Pixels whose neighbours differ (body, pattern class, colour), that carry laser light or
   straddle the lens circle are re-shaded with k x k sub-samples and box-averaged
   (`render.adaptive = false` supersamples every pixel).

The result keeps the laser light separate from the scene colour, so the "real camera" mode can
make it uneven and speckled before it is composited.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from sim_backend.fisheye_atlas import FisheyeGeometry, geometry_for, render_atlas
from sim_backend.shading import Hits, Shader
from sim_backend.world import SimWorld

_CHUNK = 400_000


@dataclass
class RenderResult:
    """A rendered frame before compositing: scene colour (H, W, 3) RGB in [0, 1] (linear light
    when the scene's tone curve is sRGB), laser light (H, W) and timings/statistics."""

    base: np.ndarray
    laser: np.ndarray
    stats: dict[str, float] = field(default_factory=dict)
    points_S: np.ndarray | None = None  # (H, W, 3) float32 surface point of each pixel centre


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
    if not isinstance(hits, Hits):
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
    points = np.full((npx, 3), np.nan, np.float32)
    for start in range(0, geo.pixel_index.size, _CHUNK):
        sl = slice(start, start + _CHUNK)
        out = shader.shade(geo.rays_S[sl], geo.atlas_xy[sl], static=static.take(sl))
        inside = geo.inside_dom[sl]
        pix = geo.pixel_index[sl]
        rgb[pix] = out.rgb * inside[:, None]
        laser[pix] = out.laser * inside
        key[pix] = np.where(inside, out.key, -32)
        if out.t is not None:
            hit = inside & np.isfinite(out.t)
            points[pix[hit]] = geo.rays_S[sl][hit] * out.t[hit, None]
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
    return RenderResult(rgb_img, laser_img, stats, points.reshape(h, w, 3))
