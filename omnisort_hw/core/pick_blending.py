"""Blend radii for consecutive moves of a pick, chosen from the clearance, and the blended
path checked where it differs from the moves.

A via point is blended with a radius no larger than the arm's clearance there (how far the arm
and what it holds are from every obstacle either move is checked against, less the collision
margin) and no larger than either move's TCP travel. Clearance at the via point bounds where a
controller may round the corner; the blended trajectory the arm will play (the core's
`plan_blended_path`, with the limits the arm plans with) is then collision-checked in its
overlap windows, the only samples where it differs from the moves already checked. A window
that comes too close halves its radius, down to a stop: blending never makes a pick refused
and never skips a check.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from omnisort_hw.core.blended_path import BlendedPath, Segment, plan_blended_path
from omnisort_hw.core.collision import (
    Box,
    Capsule,
    CollisionError,
    CollisionHit,
    FloorPlane,
    clearance,
    find_collision,
)
from omnisort_hw.core.kinematics import forward

__all__ = ["BlendedMoves", "MoveChecks", "blend_moves", "check_blends", "corner_clearance"]

# Halvings of a radius whose blend comes too close before the via point is a stop.
_HALVINGS = 3
# A radius below this (mm) is not worth halving again.
_RESOLUTION_MM = 1.0


@dataclass(frozen=True)
class MoveChecks:
    """What a move was checked against: obstacles, and whether the arm holds a cube."""

    obstacles: Sequence[Box | FloorPlane]
    holding: bool = False


@dataclass
class BlendedMoves:
    """The blend radius at the end of each move (the last is 0) and the path the arm plays."""

    blends_mm: list[float]
    path: BlendedPath

    @property
    def duration_s(self) -> float:
        return self.path.duration


def corner_clearance(
    model: Any,
    q: np.ndarray,
    obstacles: Sequence[Box | FloorPlane],
    tools: Sequence[Capsule],
    hi_mm: float,
) -> float:
    """The largest margin (mm, 0 to hi_mm) at which the arm at joints q (6,) touches nothing."""
    gap = clearance(model, q, obstacles, tool_capsules=tools)
    return float(min(max(gap, 0.0), hi_mm))


def _union(a: MoveChecks, b: MoveChecks) -> MoveChecks:
    seen = {id(o) for o in a.obstacles}
    return MoveChecks(
        [*a.obstacles, *(o for o in b.obstacles if id(o) not in seen)], a.holding or b.holding
    )


def blend_moves(
    planner: Any, q0: np.ndarray, moves: Sequence[Any], checks: Sequence[MoveChecks]
) -> BlendedMoves:
    """Blend radii for `moves` (the planner's `Move`s, consecutive from q0) from the clearance
    at each via point, and the blended path they give, collision-free in every window."""
    model, tool, margin = planner.model, planner.tool, float(planner.cfg.collision_margin_mm)
    tcp = [forward(model, np.asarray(q0, float), tool)[:3, 3]]
    tcp += [forward(model, m.q_target, tool)[:3, 3] for m in moves]
    travel = np.linalg.norm(np.diff(np.asarray(tcp), axis=0), axis=1)
    joint = [_union(checks[k], checks[k + 1]) for k in range(len(moves) - 1)]
    blends = []
    for k in range(len(moves) - 1):
        tools = planner.tool_capsules(joint[k].holding)
        reach = float(min(travel[k], travel[k + 1]))
        clear = corner_clearance(
            model, moves[k].q_target, joint[k].obstacles, tools, reach + margin
        )
        blends.append(max(0.0, min(clear - margin, reach)))
    blends.append(0.0)
    for _ in range(_HALVINGS + 1):
        path = plan_blended_path(model, q0, _segments(planner, moves, blends), tool=tool)
        bad = _bad_windows(planner, path, joint, margin)
        if not bad:
            return BlendedMoves(blends, path)
        for k in bad:
            blends[k] = 0.0 if blends[k] < 4.0 * _RESOLUTION_MM else 0.5 * blends[k]
    for k in bad:
        blends[k] = 0.0
    path = plan_blended_path(model, q0, _segments(planner, moves, blends), tool=tool)
    return BlendedMoves(blends, path)


def _segments(planner: Any, moves: Sequence[Any], blends: Sequence[float]) -> list[Segment]:
    """The moves as the arm plans them: joint moves at the joint limits, linear moves at the
    tool's limits with the joints' maxima; each brings its trajectory as planned and checked."""
    return [
        Segment("joint", m.q_target, planner.limits, r, m.traj)
        if m.kind == "joint"
        else Segment("linear", m.T_target, planner.linear_limits, r, m.traj)
        for m, r in zip(moves, blends, strict=True)
    ]


def _bad_windows(
    planner: Any, path: BlendedPath, joint: Sequence[MoveChecks], margin: float
) -> dict[int, CollisionHit]:
    """Via points whose overlap window brings the arm (or its cube) within the margin."""
    bad = {}
    q = path.trajectory.q
    for first, last, k in path.windows():
        tools = planner.tool_capsules(joint[k].holding)
        hit = find_collision(
            planner.model,
            q[first : last + 1],
            joint[k].obstacles,
            tool_capsules=tools,
            margin_mm=margin,
        )
        if hit is not None:
            bad[k] = hit
    return bad


def check_blends(
    planner: Any,
    q0: np.ndarray,
    moves: Sequence[Any],
    blends_mm: Sequence[float],
    checks: Sequence[MoveChecks],
) -> BlendedPath:
    """The blended path of `moves` with the given radii, or `CollisionError` naming the via
    point whose blended corner comes within the margin of an obstacle (nothing has moved)."""
    joint = [_union(checks[k], checks[k + 1]) for k in range(len(moves) - 1)]
    margin = float(planner.cfg.collision_margin_mm)
    path = plan_blended_path(
        planner.model, q0, _segments(planner, moves, blends_mm), tool=planner.tool
    )
    bad = _bad_windows(planner, path, joint, margin)
    if bad:
        k, hit = next(iter(bad.items()))
        raise CollisionError(
            f"blend of {blends_mm[k]:.0f} mm after {moves[k].what}: the {hit.link} would come "
            f"within {margin:g} mm of {hit.obstacle!r}"
        )
    return path
