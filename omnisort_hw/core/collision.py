"""Collision checks of planned arm motions: spheres covering capsules on the arm's links (and
on a tool or a held cube) against axis-aligned boxes and floor planes, all in the UR base
frame B, millimetres and degrees.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from omnisort_hw.core.kinematics import URModel, joint_frames
from omnisort_hw.core.motion import Trajectory
from omnisort_hw.errors import MotionRefusedError

__all__ = [
    "Box",
    "Capsule",
    "CollisionError",
    "CollisionHit",
    "FloorPlane",
    "arm_capsules",
    "check_collisions",
    "clearance",
    "collision_mask",
    "find_collision",
    "require_collision_free",
]

# Samples per chunk when only the first collision is wanted (a path that hits early stops early).
_FIRST_HIT_CHUNK = 64


class CollisionError(MotionRefusedError):
    """A planned motion would bring the arm into an obstacle."""

    code = "collision"


@dataclass(frozen=True)
class Box:
    """Axis-aligned box in B: corners lo_mm and hi_mm (3,)."""

    lo_mm: tuple[float, float, float]
    hi_mm: tuple[float, float, float]
    name: str = "box"

    def __post_init__(self) -> None:
        if not np.all(np.asarray(self.lo_mm) <= np.asarray(self.hi_mm)):
            raise ValueError(f"box {self.name!r}: lo_mm must not exceed hi_mm on any axis")


@dataclass(frozen=True)
class FloorPlane:
    """The plane z = 0 of frame F, given by its pose T_BF in B; everything below it is solid."""

    T_BF: np.ndarray = field(default_factory=lambda: np.eye(4))
    name: str = "floor"


@dataclass(frozen=True)
class Capsule:
    """A segment with a radius, fixed in DH frame `frame` (0 = base .. 6 = flange), mm.

    `static` capsules never move (the base column); they are not tested against floors,
    which they stand on.
    """

    frame: int
    start_mm: tuple[float, float, float]
    end_mm: tuple[float, float, float]
    radius_mm: float
    name: str
    static: bool = False


@dataclass(frozen=True)
class CollisionHit:
    """The first collision of a trajectory: sample index, link and obstacle names."""

    index: int
    link: str
    obstacle: str


# Envelope per model, mm: offset of the upper arm and of the forearm along the joint 2/3 axes
# from the DH plane, and radii of base/shoulder, upper arm, forearm and wrist. Approximate,
# read off UR's drawings; the sphere covering adds a margin of up to 12 % of each radius.
_ENVELOPES: dict[str, tuple[float, float, float, float, float, float]] = {
    "ur3e": (120.0, 27.0, 64.0, 50.0, 40.0, 35.0),
    "ur5e": (138.0, 7.0, 75.0, 60.0, 50.0, 45.0),
    "ur10e": (176.0, 39.0, 95.0, 75.0, 60.0, 50.0),
}


def arm_capsules(model: URModel) -> tuple[Capsule, ...]:
    """Capsules covering the arm's links, attached to the DH frames of `joint_frames`."""
    d1, _, _, d4, d5, d6 = model.d_mm
    a2, a3 = model.a_mm[1], model.a_mm[2]
    env = _ENVELOPES.get(model.name)
    if env is None:
        r = model.reach_mm
        env = (d4, 0.0, 0.09 * r, 0.07 * r, 0.06 * r, 0.05 * r)
    shoulder, fore, r_base, r_upper, r_fore, r_wrist = env
    return (
        Capsule(0, (0.0, 0.0, 0.0), (0.0, 0.0, d1), r_base, "base", static=True),
        Capsule(1, (0.0, 0.0, 0.0), (0.0, 0.0, shoulder), r_base, "shoulder"),
        Capsule(2, (0.0, 0.0, shoulder), (-a2, 0.0, shoulder), r_upper, "upper arm"),
        Capsule(2, (0.0, 0.0, shoulder), (0.0, 0.0, fore), r_upper, "elbow"),
        Capsule(3, (0.0, 0.0, fore), (-a3, 0.0, fore), r_fore, "forearm"),
        Capsule(3, (0.0, 0.0, fore), (0.0, 0.0, d4), r_wrist, "wrist 1"),
        Capsule(4, (0.0, 0.0, 0.0), (0.0, 0.0, d5), r_wrist, "wrist 2"),
        Capsule(5, (0.0, 0.0, 0.0), (0.0, 0.0, d6), r_wrist, "wrist 3"),
    )


@dataclass(frozen=True)
class _Spheres:
    """Spheres covering capsules: frame index, centre in that frame, radius, owner, static."""

    frame: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    owner: np.ndarray
    static: np.ndarray


@functools.lru_cache(maxsize=64)
def _cover(capsules: tuple[Capsule, ...]) -> _Spheres:
    """Spheres spaced at most one radius apart, enlarged so that they contain each capsule."""
    frame, centre, radius, owner, static = [], [], [], [], []
    for k, c in enumerate(capsules):
        p, q = np.asarray(c.start_mm, dtype=float), np.asarray(c.end_mm, dtype=float)
        length = float(np.linalg.norm(q - p))
        n = max(1, int(np.ceil(length / c.radius_mm)))
        f = np.linspace(0.0, 1.0, n + 1)
        centre.append(p + f[:, None] * (q - p))
        h = length / n
        radius.append(np.full(n + 1, np.hypot(c.radius_mm, 0.5 * h)))
        frame.append(np.full(n + 1, c.frame))
        owner.append(np.full(n + 1, k))
        static.append(np.full(n + 1, c.static))
    return _Spheres(
        np.concatenate(frame),
        np.concatenate(centre),
        np.concatenate(radius),
        np.concatenate(owner),
        np.concatenate(static),
    )


@functools.lru_cache(maxsize=64)
def _bounds(
    capsules: tuple[Capsule, ...],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One sphere per capsule that contains all of its covering spheres (frame, centre,
    radius), and each capsule's covering spheres (C, n) padded with -1.

    The broad phase: a covering sphere can only touch a box its capsule's sphere touches."""
    sp = _cover(capsules)
    frame = np.array([c.frame for c in capsules])
    mid = np.array([0.5 * (np.add(c.start_mm, c.end_mm)) for c in capsules], dtype=float)
    reach = np.linalg.norm(sp.centre - mid[sp.owner], axis=1) + sp.radius
    radius = np.zeros(len(capsules))
    np.maximum.at(radius, sp.owner, reach)
    counts = np.bincount(sp.owner, minlength=len(capsules))
    members = np.full((len(capsules), int(counts.max())), -1)
    for k in range(len(capsules)):
        idx = np.flatnonzero(sp.owner == k)
        members[k, : idx.size] = idx
    return frame, mid, radius, members


def _box_contact(pts: np.ndarray, r: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(c, K, B) True where the sphere at pts (c, K, 3) with radius r (K,) reaches a box."""
    gap = np.maximum(lo - pts[:, :, None, :], 0.0) + np.maximum(pts[:, :, None, :] - hi, 0.0)
    return np.einsum("ckbi,ckbi->ckb", gap, gap) <= (r * r)[None, :, None]


def _hits(
    model: URModel,
    q: np.ndarray,
    obstacles: Sequence[Box | FloorPlane],
    capsules: Sequence[Capsule],
    margin_mm: float,
    first_only: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per sample (M,): any hit, and the first hit's capsule and obstacle index (-1 if none).
    With `first_only`, samples after the chunk of the first hit are left unchecked (False).

    Boxes are tested in two stages: one bounding sphere per capsule first, then the covering
    spheres only at the samples where a bounding sphere reached a box (the same answer as
    testing every covering sphere, at a fraction of the cost)."""
    capsules = tuple(capsules)
    sp = _cover(capsules)
    m = q.shape[0]
    any_hit = np.zeros(m, dtype=bool)
    who = np.full(m, -1)
    what = np.full(m, -1)
    if not obstacles or m == 0:
        return any_hit, who, what
    boxes = [i for i, o in enumerate(obstacles) if isinstance(o, Box)]
    planes = [i for i, o in enumerate(obstacles) if isinstance(o, FloorPlane)]
    box_obs = [o for o in obstacles if isinstance(o, Box)]
    plane_obs = [o for o in obstacles if isinstance(o, FloorPlane)]
    lo = np.array([o.lo_mm for o in box_obs], dtype=float).reshape(-1, 3)
    hi = np.array([o.hi_mm for o in box_obs], dtype=float).reshape(-1, 3)
    normals = np.array([o.T_BF[:3, 2] for o in plane_obs], dtype=float).reshape(-1, 3)
    offsets = np.array([o.T_BF[:3, 2] @ o.T_BF[:3, 3] for o in plane_obs])
    order = np.array(boxes + planes, dtype=int)
    r = sp.radius + margin_mm
    b_frame, b_mid, b_radius, members = _bounds(capsules)
    b_r = b_radius + margin_mm
    moving = np.array([not k.static for k in capsules])  # static capsules stand on floors
    chunk = max(1, 2**20 // max(1, sp.radius.size * max(1, len(boxes))))
    if first_only:
        chunk = min(chunk, _FIRST_HIT_CHUNK)
    for start in range(0, m, chunk):
        if first_only and any_hit[:start].any():
            break
        frames = joint_frames(model, q[start : start + chunk])  # (c, 7, 4, 4)
        c = frames.shape[0]
        hit = np.zeros((c, sp.radius.size, order.size), dtype=bool)
        Fb = frames[:, b_frame]
        mids = (Fb[..., :3, :3] @ b_mid[..., None])[..., 0] + Fb[..., :3, 3]  # (c, C, 3)
        si = ci = bi = np.empty(0, dtype=int)
        if boxes:
            si, ci, bi = np.nonzero(_box_contact(mids, b_r, lo, hi))
        low = np.empty(0, dtype=int)
        if planes:
            near_floor = (mids @ normals.T - offsets < b_r[None, :, None]) & moving[None, :, None]
            low = np.flatnonzero(near_floor.any(axis=(1, 2)))
        rows = np.union1d(si, low)
        if rows.size:
            F = frames[rows][:, sp.frame]  # (R, K, 4, 4)
            pts = np.zeros((c, sp.radius.size, 3))
            pts[rows] = (F[..., :3, :3] @ sp.centre[..., None])[..., 0] + F[..., :3, 3]
            if si.size:
                # Covering spheres of the capsule only, against the box its bound reached.
                sph = members[ci]  # (T, n), -1 padded
                p = pts[si[:, None], np.maximum(sph, 0)]  # (T, n, 3)
                gap = np.maximum(lo[bi][:, None] - p, 0.0) + np.maximum(p - hi[bi][:, None], 0.0)
                rr = r[np.maximum(sph, 0)]
                touch = (np.einsum("tni,tni->tn", gap, gap) <= rr * rr) & (sph >= 0)
                t_i, n_i = np.nonzero(touch)
                hit[si[t_i], sph[t_i, n_i], bi[t_i]] = True
            if low.size:
                height = pts[low] @ normals.T - offsets
                above = ~sp.static[None, :, None]  # static capsules stand on floors
                hit[low, :, len(boxes) :] = (height < r[None, :, None]) & above
        flat = hit.reshape(c, -1)
        first = np.argmax(flat, axis=1)
        sel = slice(start, start + c)
        any_hit[sel] = flat.any(axis=1)
        who[sel] = np.where(any_hit[sel], sp.owner[first // hit.shape[2]], -1)
        what[sel] = np.where(any_hit[sel], order[first % hit.shape[2]], -1)
    return any_hit, who, what


def collision_mask(
    model: URModel,
    q_deg: np.ndarray,
    obstacles: Sequence[Box | FloorPlane],
    *,
    tool_capsules: Sequence[Capsule] = (),
    margin_mm: float = 0.0,
) -> np.ndarray:
    """(M,) True where the arm at joints q (M, 6) deg touches an obstacle (within margin_mm)."""
    q = np.asarray(q_deg, dtype=float).reshape(-1, 6)
    return _hits(model, q, obstacles, (*arm_capsules(model), *tool_capsules), margin_mm)[0]


def clearance(
    model: URModel,
    q_deg: np.ndarray,
    obstacles: Sequence[Box | FloorPlane],
    *,
    tool_capsules: Sequence[Capsule] = (),
) -> float:
    """The margin (mm) at which the arm at joints q (6,) deg first touches an obstacle, as
    `collision_mask` sees it (negative when it already does; inf without obstacles)."""
    sp = _cover((*arm_capsules(model), *tool_capsules))
    F = joint_frames(model, np.asarray(q_deg, dtype=float).reshape(1, 6))[0][sp.frame]
    pts = (F[:, :3, :3] @ sp.centre[:, :, None])[:, :, 0] + F[:, :3, 3]
    gaps = [np.inf]
    for o in obstacles:
        if isinstance(o, Box):
            gap = np.maximum(o.lo_mm - pts, 0.0) + np.maximum(pts - o.hi_mm, 0.0)
            gaps.append(float(np.min(np.linalg.norm(gap, axis=1) - sp.radius)))
        elif (~sp.static).any():
            n = o.T_BF[:3, 2]
            height = pts[~sp.static] @ n - n @ o.T_BF[:3, 3]
            gaps.append(float(np.min(height - sp.radius[~sp.static])))
    return min(gaps)


def find_collision(
    model: URModel,
    q_deg: np.ndarray,
    obstacles: Sequence[Box | FloorPlane],
    *,
    tool_capsules: Sequence[Capsule] = (),
    margin_mm: float = 0.0,
    max_step_deg: float = 1.0,
) -> CollisionHit | None:
    """The first collision along joint samples q (M, 6) deg, or None.

    Consecutive samples further apart than `max_step_deg` (any joint) are subdivided in
    joint space, so thin obstacles between samples are found; a collision on the way from
    sample i-1 to sample i is reported as index i. Tool capsules are attached to frame 6.
    """
    q = np.asarray(q_deg, dtype=float).reshape(-1, 6)
    if q.shape[0] == 0:
        return None
    step = np.diff(q, axis=0)
    n_sub = np.maximum(1, np.ceil(np.max(np.abs(step), axis=1) / max_step_deg)).astype(int)
    seg = np.repeat(np.arange(q.shape[0] - 1), n_sub)
    starts = np.cumsum(n_sub) - n_sub
    frac = (np.arange(seg.size) - starts[seg] + 1) / n_sub[seg]
    dense = np.concatenate([q[:1], q[seg] + frac[:, None] * step[seg]])
    owner_sample = np.concatenate([[0], seg + 1])
    capsules = (*arm_capsules(model), *tool_capsules)
    hit, who, what = _hits(model, dense, obstacles, capsules, margin_mm, first_only=True)
    if not hit.any():
        return None
    i = int(np.argmax(hit))
    return CollisionHit(
        index=int(owner_sample[i]), link=capsules[who[i]].name, obstacle=obstacles[what[i]].name
    )


def check_collisions(
    model: URModel,
    q_deg: np.ndarray,
    obstacles: Sequence[Box | FloorPlane],
    *,
    tool_capsules: Sequence[Capsule] = (),
    margin_mm: float = 0.0,
    max_step_deg: float = 1.0,
) -> int | None:
    """Index of the first colliding sample of q (M, 6) deg, or None (see `find_collision`)."""
    hit = find_collision(
        model,
        q_deg,
        obstacles,
        tool_capsules=tool_capsules,
        margin_mm=margin_mm,
        max_step_deg=max_step_deg,
    )
    return None if hit is None else hit.index


def require_collision_free(
    model: URModel,
    trajectory: Trajectory,
    obstacles: Sequence[Box | FloorPlane],
    *,
    tool_capsules: Sequence[Capsule] = (),
    margin_mm: float = 0.0,
) -> None:
    """Raise CollisionError naming the link, the obstacle and the time of the first contact."""
    hit = find_collision(
        model, trajectory.q, obstacles, tool_capsules=tool_capsules, margin_mm=margin_mm
    )
    if hit is not None:
        raise CollisionError(
            f"the {model.name}'s {hit.link} would hit {hit.obstacle!r} at "
            f"t = {trajectory.t[hit.index]:.2f} s of a {trajectory.kind} move; "
            "re-plan around it or move the obstacle in the cell configuration"
        )
