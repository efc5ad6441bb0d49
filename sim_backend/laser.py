"""The laser plane, its shadows, and the exact laser/scene intersection polylines.

The emitter sits at E = (0, 0, -d). A point is lit when nothing lies between E and it:
`LaserFan` casts a fan of rays in the plane (pybullet `rayTestBatch` on the collision shapes),
each direction when a frame first needs it, and keeps the first hit distance per direction, in
a few sheets parallel to the plane across the light's thickness; a stripe sample is lit when its
range within its own sheet does not exceed that sheet's distance (interpolated between the cast
sheets). The polylines intersect the plane with every known planar face analytically and keep
the parts the camera sees and the laser reaches.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import pybullet as p

if TYPE_CHECKING:
    from sim_backend.world import SimWorld

MM = 1e-3
HALL_RADIUS_MM = 9000.0
FAN_RAYS = 14400
FAN_RANGE_MM = 15000.0
FAN_SHEETS = 5  # sheets across the light's thickness (their ranges are interpolated)
_BATCH = 1000  # rays per pybullet call: each holds the GIL ~3 ms (8000: 20-40 ms)


@dataclass(frozen=True)
class LaserPlane:
    """The plane through the emitter (0, 0, -d) with unit normal n (docs/frames.md), in S (mm):
    n . X + d n_z = 0. e1, e2 span the plane."""

    normal: np.ndarray
    distance: float

    @property
    def offset(self) -> float:
        """The plane's constant: n . X + offset = 0 (offset = d n_z, so the emitter is on it)."""
        return float(self.distance * self.normal[2])

    @property
    def emitter(self) -> np.ndarray:
        """The emitter's position in S (mm)."""
        return np.array([0.0, 0.0, -self.distance])

    @property
    def basis(self) -> tuple[np.ndarray, np.ndarray]:
        """Orthonormal in-plane directions: e1 near +X, e2 = n x e1 (near +Y)."""
        n = self.normal
        e1 = np.array([1.0, 0.0, 0.0]) - n[0] * n
        e1 /= np.linalg.norm(e1)
        return e1, np.cross(n, e1)

    def signed_distance(self, pts: np.ndarray) -> np.ndarray:
        """Signed distance (mm) of points (..., 3) to the plane."""
        return np.asarray(pts) @ self.normal + self.offset


def ray_hits(
    client: int, starts_mm: np.ndarray, ends_mm: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """First hit (body id, fraction in [0, 1]) of segments start -> end, batched."""
    ids = np.empty(len(starts_mm), np.int64)
    frac = np.empty(len(starts_mm))
    for k in range(0, len(starts_mm), _BATCH):
        res = p.rayTestBatch(
            (starts_mm[k : k + _BATCH] * MM).tolist(),
            (ends_mm[k : k + _BATCH] * MM).tolist(),
            physicsClientId=client,
        )
        ids[k : k + len(res)] = [r[0] for r in res]
        frac[k : k + len(res)] = [r[2] for r in res]
    frac[ids < 0] = 1.0
    return ids, frac


@dataclass(frozen=True)
class LaserFan:
    """First-hit range (mm) of the laser light per direction (FAN_RAYS bins) in the plane and in
    the sheets parallel to it at `offsets` (mm): the light off the plane travels in its own
    sheet, so a grazing surface (the floor) is reached at a range that changes with the offset,
    and judging an off-plane point by the plane's own range would shadow half of its band.

    The rays are cast when a direction is first asked for (`lit`), in every sheet at once: a
    frame's stripe uses a fraction of the fan, and a direction's rays are the same whenever
    they are cast. So a fan belongs to one state of the world (one render)."""

    plane: LaserPlane
    client: int
    offsets: np.ndarray
    ranges: np.ndarray = field(init=False)  # (len(offsets), FAN_RAYS), NaN where not cast yet

    def __post_init__(self) -> None:
        object.__setattr__(self, "ranges", np.full((len(self.offsets), FAN_RAYS), np.nan))

    @classmethod
    def compute(cls, world: SimWorld, plane: LaserPlane, half_width_mm: float = 0.0) -> LaserFan:
        """The fan in `world` (collision shapes; the emitter housing has none), in FAN_SHEETS
        sheets across +-`half_width_mm` (one sheet, the plane, when 0)."""
        offsets = np.linspace(-half_width_mm, half_width_mm, FAN_SHEETS if half_width_mm else 1)
        return cls(plane, world.client, offsets)

    def _cast(self, bins: np.ndarray) -> None:
        """Cast the directions `bins` in every sheet and store their first-hit ranges."""
        phi = bins * (2.0 * np.pi / FAN_RAYS)
        e1, e2 = self.plane.basis
        dirs = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
        for j, off in enumerate(self.offsets):
            emitter = self.plane.emitter + off * self.plane.normal
            ids, frac = ray_hits(self.client, emitter + dirs * 1.0, emitter + dirs * FAN_RANGE_MM)
            self.ranges[j, bins] = np.where(ids >= 0, 1.0 + frac * (FAN_RANGE_MM - 1.0), np.inf)

    def lit(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(lit flags, range from the emitter in mm) of points near the plane: each point's
        range within its own sheet against that sheet's reach, interpolated between the two
        nearest cast sheets (exact on a planar surface, whose range is linear in the offset)."""
        off = self.plane.signed_distance(pts)
        rel = pts - self.plane.emitter
        rel = rel - np.outer(rel @ self.plane.normal, self.plane.normal)
        e1, e2 = self.plane.basis
        phi = np.arctan2(rel @ e2, rel @ e1)
        rng = np.linalg.norm(rel, axis=1)
        k = np.rint(phi / (2.0 * np.pi) * FAN_RAYS).astype(np.int64) % FAN_RAYS
        # Neighbouring bins guard against the quantisation of directions at grazing surfaces.
        near = (k, (k + 1) % FAN_RAYS, (k - 1) % FAN_RAYS)
        need = np.unique(np.concatenate(near))
        todo = need[np.isnan(self.ranges[0, need])]
        if todo.size:
            self._cast(todo)
        r = self.ranges
        reach_all = np.maximum.reduce([r[:, b] for b in near])
        if len(self.offsets) == 1:
            reach = reach_all[0]
        else:
            step = self.offsets[1] - self.offsets[0]
            x = np.clip((off - self.offsets[0]) / step, 0.0, len(self.offsets) - 1.0)
            i0 = np.minimum(x.astype(np.int64), len(self.offsets) - 2)
            f = x - i0
            cols = np.arange(len(pts))
            r0, r1 = reach_all[i0, cols], reach_all[i0 + 1, cols]
            with np.errstate(invalid="ignore"):
                lerp = r0 + f * (r1 - r0)
            # Where one sheet escapes (no hit), the light between them is not stopped earlier
            # than the nearer sheet's hit: take the farther reach.
            reach = np.where(np.isfinite(r0) & np.isfinite(r1), lerp, np.maximum(r0, r1))
        tol = 2.0 + rng * (2.0 * np.pi / FAN_RAYS) * 2.0
        return rng <= reach + tol, rng


@dataclass(frozen=True)
class Polyline:
    """A visible, lit piece of the laser/scene intersection on one named face."""

    surface: str
    points: np.ndarray


def visible_from(
    client: int, origin: np.ndarray, pts: np.ndarray, margin_mm: float = 0.5
) -> np.ndarray:
    """True where nothing blocks the segment from `origin` to within `margin_mm` of each point."""
    vec = pts - origin
    dist = np.linalg.norm(vec, axis=1)
    ends = origin + vec * ((dist - margin_mm) / dist)[:, None]
    ids, _ = ray_hits(client, np.repeat(origin[None], len(pts), axis=0), ends)
    return ids < 0


FACE_LIFT_MM = 1.0  # off a face, for its visibility test (more than the engine's margin)


def laser_polylines(
    world: SimWorld,
    plane: LaserPlane,
    in_view: Callable[[np.ndarray], np.ndarray],
    step_mm: float = 0.5,
) -> list[Polyline]:
    """Exact plane/face intersections, kept where seen by the camera and lit by the laser.

    Each face segment is sampled every `step_mm`; a sample survives when the face looks at
    both the camera and the emitter, nothing blocks either view, and `in_view` (inside the
    lens circle) holds. Runs of survivors become polylines (end points to within `step_mm`).
    """
    out: list[Polyline] = []
    cam = np.zeros(3)
    emitter = plane.emitter
    for name, body, rect in world.laser_rects():
        if body in world.info.no_laser:
            continue
        seg = rect.plane_segment(plane.normal, -plane.offset)
        if seg is None:
            continue
        a, b = seg
        length = float(np.linalg.norm(b - a))
        n = max(2, int(np.ceil(length / step_mm)) + 1)
        pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        ok = ((cam - pts) @ rect.normal > 0) & ((emitter - pts) @ rect.normal > 0)
        ok &= in_view(pts)
        if name == "floor":
            ok &= np.hypot(pts[:, 0], pts[:, 1]) < HALL_RADIUS_MM
        idx = np.flatnonzero(ok)
        # the rays end just off the face: ending them on it, a face seen or lit at a grazing
        # angle hid itself (the physics engine's collision margin) and cut gaps into its line
        lifted = pts + FACE_LIFT_MM * rect.normal
        if idx.size:
            ok[idx] = visible_from(world.client, cam, lifted[idx])
            idx = np.flatnonzero(ok)
        if idx.size:
            ok[idx] = visible_from(world.client, emitter, lifted[idx])
        if not ok.any():
            continue
        edges = np.diff(np.concatenate([[0], ok.astype(np.int8), [0]]))
        for s, e in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
            if e - s >= 2:
                out.append(Polyline(name, pts[s:e]))
    return out
