"""Shading of camera rays in the simulated cell: exact static geometry, the raster, the laser.

`Shader.shade()` takes any set of rays: the atlas (`fisheye_atlas.py`) gives the body each ray
hits; target walls and checkerboards are intersected analytically with their plane and shaded
from the exact point (patterns, markers, borders); the floor is analytic too; other bodies use
pybullet's colour and depth. The laser intensity comes from the signed distance of the 3D point
to the laser plane, a Gaussian across the plane, the range fall-off and a shadow test.

Separate from `render.py` because it works on rays, not pixels: the frame loop calls it once
for the pixel centres and again for the sub-samples of the pixels it supersamples.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from omnisort_hw.core.radiometry import srgb_to_linear
from sim_backend.fisheye_atlas import Atlas, remap_flat
from sim_backend.laser import HALL_RADIUS_MM, LaserFan, LaserPlane
from sim_backend.world import AnalyticBox, AnalyticCylinder, Panel, SimWorld

_BAND_SIGMAS = 5.0  # the stripe's Gaussian is drawn (and its shadows cast) out to this many sigma


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
    t: np.ndarray | None = None  # distance along the ray (mm), for the sensor's light effects


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
        las = scene.laser
        self.sigma = las.width_mm / (2.0 * np.sqrt(2.0 * np.log(2.0)))
        self.fan = (
            LaserFan.compute(world, self.plane, _BAND_SIGMAS * self.sigma) if laser_on else None
        )
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
        entry_axis = np.where(tmin == n0, 0, np.where(tmin == n1, 1, 2))
        d_axis = np.where(entry_axis == 0, dirs[0], np.where(entry_axis == 1, dirs[1], dirs[2]))
        hit = (tmin <= far) & (tmin > 0)
        face = 2 * entry_axis + (d_axis > 0)
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
        return Shaded(rgb, laser, hits.key, hits.t)

    def _laser(self, rays: np.ndarray, hits: Hits, out: np.ndarray) -> None:
        """Stripe intensity: Gaussian in the signed distance to the plane, fall-off, shadows."""
        assert self.fan is not None
        las = self.world.scene.laser
        with np.errstate(invalid="ignore"):
            s = hits.t * (rays @ self.plane.normal.astype(np.float32)) + np.float32(
                self.plane.offset
            )
        near = np.abs(s) < _BAND_SIGMAS * self.sigma
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
