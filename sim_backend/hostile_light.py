"""Hostile light for the simulated camera: the scene options a real cell meets.

* `sunlight`: a window's parallel sunbeam: every surface point whose path towards the sun
  passes through the window (a rectangle high above the cell) gets strong, steady, warm white
  light; the patch crosses the floor and a target wall. (No shadow test inside the beam.)
* `red_objects`: every cube is red, and red tape (painted volumes) crosses the laser line on
  both target walls and lies on the floor next to it.
* `specular`: a glossy floor mirrors the laser light of every lit point above it, as a fainter
  second line (the mirror image is projected through the camera and seen where the camera
  sees the floor).
* `saturated`: a laser strong enough to clip the stripe core at the capture's default exposure.
* `flicker`: lamps on the mains at 40 % modulation (100 Hz), unsynchronised with the camera.

Each is a `Lighting` record: scene changes plus light the sensor adds (`extra_light`). All of
it is deterministic; the per-frame randomness (flicker phase, noise) is the sensor's.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.radiometry import srgb_to_linear
from sim_backend.scene import Color, Scene

SCENARIOS = ("sunlight", "red_objects", "specular", "saturated", "flicker")
DEFAULT_FLICKER = 0.05  # LED drivers and ballasts always leave a little ripple
_RED = np.array([0.80, 0.05, 0.04], np.float32)  # tape colour (linear light)


@dataclass(frozen=True)
class Lighting:
    """One lighting condition of the simulated cell (`normal` is the plain lamps)."""

    name: str = "normal"
    flicker_depth: float = DEFAULT_FLICKER
    laser_gain: float = 1.0
    sun: float = 0.0  # sunlight on a sunlit surface, relative to the lamps
    sun_direction: tuple[float, float, float] = (0.45, -0.25, -0.86)  # travel direction, S
    window_mm: tuple[float, float, float, float] = (-1250.0, -600.0, 1185.0, 1685.0)  # x0 x1 y y
    window_z_mm: float = 1500.0
    red: bool = False
    mirror: float = 0.0  # floor reflectivity for the laser light


def lighting(name: str) -> Lighting:
    """The named scenario (or `normal`); ValueError names the known ones."""
    table = {
        "normal": Lighting(),
        "sunlight": Lighting("sunlight", sun=3.0),
        "red_objects": Lighting("red_objects", red=True),
        "specular": Lighting("specular", mirror=0.35),
        "saturated": Lighting("saturated", laser_gain=8.0),
        "flicker": Lighting("flicker", flicker_depth=0.4),
    }
    if name not in table:
        raise ValueError(f"unknown lighting {name!r} (known: {', '.join(table)})")
    return table[name]


def apply_to_scene(scene: Scene, light: Lighting) -> Scene:
    """The scene with the lighting's own changes (red cubes, laser power)."""
    out = scene
    if light.red and scene.cubes:
        from dataclasses import replace

        red = Color("rgb", (0.85, 0.08, 0.06))
        out = out.replace(cubes=tuple(replace(c, color=red) for c in scene.cubes))
    if light.laser_gain != 1.0:
        out = out.replace(laser={"intensity": scene.laser.intensity * light.laser_gain})
    return out


def _tape_mask(points: np.ndarray, scene: Scene) -> np.ndarray:
    """Pixels whose surface point lies in a strip of red tape: 50 mm wide vertical strips on
    both inner target walls crossing the laser's height, and a strip on the floor beside the
    stripe's foot on each wall."""
    x, y, z = points[..., 0], points[..., 1], points[..., 2]
    t = scene.target
    floor = scene.floor_z
    cx, cy = t.center_mm if t is not None else (0.0, 650.0)
    half = (t.separation_mm / 2.0) if t is not None else 540.0
    plane_z = -scene.laser.distance_mm
    mask = np.zeros(points.shape[:2], bool)
    with np.errstate(invalid="ignore"):
        for side in (-1.0, 1.0):
            wall_x = cx + side * half
            near_wall = np.abs(x - wall_x) < 5.0
            strip = near_wall & (np.abs(y - (cy + 0.15 * side * half)) < 25.0)
            strip &= (z > floor) & (z < plane_z + 150.0)
            on_floor = (np.abs(z - floor) < 2.0) & (np.abs(x - (wall_x - side * 120.0)) < 25.0)
            on_floor &= np.abs(y - cy) < 300.0
            mask |= strip | on_floor
    return mask


def _sun_mask(points: np.ndarray, light: Lighting) -> np.ndarray:
    """Pixels whose point sees the sun through the window (a parallel beam)."""
    d = np.asarray(light.sun_direction, np.float64)
    d /= np.linalg.norm(d)
    with np.errstate(invalid="ignore"):
        s = (light.window_z_mm - points[..., 2]) / -d[2]  # back along the beam to the window
        wx = points[..., 0] - s * d[0]
        wy = points[..., 1] - s * d[1]
        x0, x1, y0, y1 = light.window_mm
        return (s > 0) & (wx > x0) & (wx < x1) & (wy > y0) & (wy < y1)


def _mirror_laser(
    laser: np.ndarray,
    points: np.ndarray,
    floor_z: float,
    model: OcamModel,
    R_SC: np.ndarray,
    reflectivity: float,
) -> np.ndarray:
    """(H, W) laser light reflected by the floor: each lit point above the floor is mirrored
    in it and splatted (bilinear) at the pixel where the camera sees the mirror image, kept
    where that pixel sees the floor."""
    h, w = laser.shape
    lit = np.flatnonzero((laser > 1e-3).ravel())
    pts = points.reshape(-1, 3)[lit].astype(np.float64)
    keep = np.isfinite(pts).all(axis=1) & (pts[:, 2] > floor_z + 1.0)
    lit, pts = lit[keep], pts[keep]
    out: np.ndarray = np.zeros((h, w), np.float32)
    if lit.size == 0:
        return out
    pts[:, 2] = 2.0 * floor_z - pts[:, 2]
    px = model.ray_to_pixel(pts @ R_SC)
    val = laser.ravel()[lit] * np.float32(reflectivity)
    u0 = np.floor(px[:, 0]).astype(np.int64)
    v0 = np.floor(px[:, 1]).astype(np.int64)
    fu, fv = px[:, 0] - u0, px[:, 1] - v0
    for du, dv, wt in (
        (0, 0, (1 - fu) * (1 - fv)),
        (1, 0, fu * (1 - fv)),
        (0, 1, (1 - fu) * fv),
        (1, 1, fu * fv),
    ):
        uu, vv = u0 + du, v0 + dv
        ok = (uu >= 0) & (uu < w) & (vv >= 0) & (vv < h)
        np.add.at(out, (vv[ok], uu[ok]), (val[ok] * wt[ok]).astype(np.float32))
    out = cv2.GaussianBlur(out, (0, 0), 0.7)
    with np.errstate(invalid="ignore"):
        sees_floor = np.abs(points[..., 2] - floor_z) < 1.0
    return np.where(sees_floor, out, 0.0).astype(np.float32)


def extra_light(
    base: np.ndarray,
    laser: np.ndarray,
    points: np.ndarray,
    scene: Scene,
    model: OcamModel,
    R_SC: np.ndarray,
    light: Lighting,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(lamp-lit colour, steady light or None, extra laser light or None) for one render.
    `base` is linear light; `points` the (H, W, 3) surface points in S (NaN: none)."""
    steady = None
    extra = None
    if light.red:
        mask = _tape_mask(points, scene)
        shade = np.float32(scene.render.ambient + 0.5 * scene.render.diffuse)
        base = np.where(mask[..., None], _RED * shade, base).astype(np.float32)
    if light.sun > 0:
        warm = srgb_to_linear(np.array([1.0, 0.96, 0.88], np.float32))
        steady = (base * _sun_mask(points, light)[..., None] * warm * light.sun).astype(np.float32)
    if light.mirror > 0:
        colour = np.asarray(scene.laser.color.rgb, np.float32)
        mirrored = _mirror_laser(laser, points, scene.floor_z, model, R_SC, light.mirror)
        extra = mirrored[..., None] * colour
    return base, steady, extra
