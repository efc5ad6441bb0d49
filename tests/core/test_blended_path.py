"""Blended paths (`core.blended_path`) and their radii from the clearance (`core.pick_blending`).

Tolerances: a blended path ends on the exact last sample of its last move; "within the blend
radius" is by construction (the overlap starts on a sample inside the sphere), so it is
checked with no slack; joint rates are checked by finite differences of the 2 ms samples
against the moves' limits with the planner's own slack (0.1 % speed, 1 % acceleration).
"""

from __future__ import annotations

import numpy as np
import pytest

from omnisort_hw.core.blended_path import (
    PATH_RATE_HZ,
    Segment,
    plan_blended_path,
    resample,
)
from omnisort_hw.core.collision import Box, CollisionError, find_collision
from omnisort_hw.core.kinematics import forward, get_model
from omnisort_hw.core.motion import MotionLimits
from omnisort_hw.core.pick_blending import MoveChecks, blend_moves, check_blends
from omnisort_hw.core.pick_planning import Planner, SortConfig

MODEL = get_model("ur5e")
TOOL = np.eye(4)
TOOL[2, 3] = 150.0
JOINT = MotionLimits(joint_speed_deg_s=120.0, joint_acc_deg_s2=240.0)
LINEAR = MotionLimits(
    joint_speed_deg_s=180.0,
    joint_acc_deg_s2=300.0,
    linear_speed_mm_s=300.0,
    linear_acc_mm_s2=1200.0,
)
Q0 = np.array([0.0, -90.0, 90.0, -90.0, -90.0, 0.0])
Q1 = Q0 + np.array([40.0, -20.0, 10.0, 0.0, 0.0, 0.0])
Q2 = Q1 + np.array([40.0, 20.0, -10.0, 5.0, 0.0, 0.0])


def _path(r1: float, r2: float):
    T3 = forward(MODEL, Q2, TOOL)
    T3[2, 3] -= 100.0
    segs = [
        Segment("joint", Q1, JOINT, r1),
        Segment("joint", Q2, JOINT, r2),
        Segment("linear", T3, LINEAR),
    ]
    return plan_blended_path(MODEL, Q0, segs, tool=TOOL), T3


def _tcp(q: np.ndarray) -> np.ndarray:
    return forward(MODEL, q, TOOL)[..., :3, 3]


@pytest.mark.parametrize("radius", [20.0, 50.0, 120.0])
def test_blended_path_ends_on_target_passes_within_the_radius_and_is_quicker(
    radius: float,
) -> None:
    path, T3 = _path(radius, radius)
    q = path.trajectory.q
    np.testing.assert_array_equal(q[0], Q0)
    np.testing.assert_array_equal(q[-1], path.moves[-1].q[-1])
    np.testing.assert_allclose(_tcp(q[-1]), T3[:3, 3], atol=1e-6)
    p = _tcp(q)
    for via in (Q1, Q2):
        closest = float(np.min(np.linalg.norm(p - _tcp(via), axis=1)))
        assert 0.0 < closest <= radius, (via, closest)
    assert np.all(path.overlaps > 0)
    saved = path.stopped_duration - path.duration
    assert saved == pytest.approx(path.overlaps.sum() / PATH_RATE_HZ)
    assert saved > 0.1, saved


def test_a_zero_radius_stops_on_the_via_point() -> None:
    path, _ = _path(0.0, 0.0)
    assert path.duration == pytest.approx(path.stopped_duration)
    p = _tcp(path.trajectory.q)
    for via in (Q1, Q2):
        assert float(np.min(np.linalg.norm(p - _tcp(via), axis=1))) < 1e-9
    assert path.windows() == []


def test_joint_rates_stay_within_the_moves_limits() -> None:
    segs = [Segment("joint", Q1, JOINT, 200.0), Segment("joint", Q2, JOINT)]
    path = plan_blended_path(MODEL, Q0, segs, tool=TOOL)
    assert path.overlaps[0] > 0
    dt = 1.0 / PATH_RATE_HZ
    qd = np.diff(path.trajectory.q, axis=0) / dt
    qdd = np.diff(qd, axis=0) / dt
    assert np.max(np.abs(qd)) <= 120.0 * 1.001
    assert np.max(np.abs(qdd)) <= 240.0 * 1.01


def test_a_reversing_joint_is_not_blended_past_its_acceleration() -> None:
    """Joint 2 runs out and back: braking and starting again add up, so the blend shrinks
    until the sum is within the limit (here to a stop)."""
    q1 = Q0 + np.array([0.0, 30.0, 0.0, 0.0, 0.0, 0.0])
    segs = [Segment("joint", q1, JOINT, 300.0), Segment("joint", Q0, JOINT)]
    path = plan_blended_path(MODEL, Q0, segs, tool=TOOL)
    dt = 1.0 / PATH_RATE_HZ
    qdd = np.diff(path.trajectory.q, n=2, axis=0) / dt**2
    assert np.max(np.abs(qdd)) <= 240.0 * 1.01


def test_outside_its_windows_the_path_is_its_moves() -> None:
    path, _ = _path(50.0, 50.0)
    q = path.trajectory.q
    inside = np.zeros(len(q), dtype=bool)
    for first, last, _k in path.windows():
        inside[first : last + 1] = True
    for start, move in zip(path.starts, path.moves, strict=True):
        idx = start + np.arange(len(move))
        keep = ~inside[idx]
        np.testing.assert_allclose(q[idx[keep]], move.q[keep], atol=1e-9)


def test_resample_keeps_the_ends_and_the_duration_within_one_period() -> None:
    path, _ = _path(50.0, 50.0)
    for rate in (240.0, 500.0):
        r = resample(path.trajectory, rate)
        np.testing.assert_array_equal(r.q[0], path.trajectory.q[0])
        np.testing.assert_array_equal(r.q[-1], path.trajectory.q[-1])
        assert -1e-9 <= r.duration - path.duration < 1.0 / rate
        np.testing.assert_allclose(np.diff(r.t), 1.0 / rate)


# A corner the moves clear and a 300 mm blend cuts: a 20 mm post inside it (found by search
# around the blended path and kept; the test checks both facts before relying on them).
POST = Box(np.array([-305.0, -600.0, 376.0]), np.array([-285.0, -580.0, 396.0]), "post")


def _corner() -> tuple[Planner, list, np.ndarray]:
    planner = Planner(SortConfig(floor_z_B_mm=-900.0), np.eye(4))
    q1 = Q0 + np.array([60.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    q2 = q1 + np.array([0.0, 30.0, -50.0, 20.0, 0.0, 0.0])
    moves = [
        planner.plan_joint(Q0, q1, [POST], "turn"),
        planner.plan_joint(q1, q2, [POST], "reach"),
    ]
    return planner, moves, Q0


def test_a_blended_corner_that_would_hit_is_refused_and_the_radius_comes_from_the_clearance() -> (
    None
):
    planner, moves, q0 = _corner()
    checks = [MoveChecks([POST]), MoveChecks([POST])]
    poly = np.concatenate([m.traj.q for m in moves])
    tools = planner.gripper
    assert find_collision(planner.model, poly, [POST], tool_capsules=tools, margin_mm=10.0) is None
    with pytest.raises(CollisionError, match="blend of 300 mm after turn"):
        check_blends(planner, q0, moves, [300.0, 0.0], checks)
    chosen = blend_moves(planner, q0, moves, checks)
    r = chosen.blends_mm[0]
    assert 0.0 < r < 300.0 and chosen.blends_mm[-1] == 0.0
    check_blends(planner, q0, moves, chosen.blends_mm, checks)  # its windows are clear
    free = blend_moves(planner, q0, moves, [MoveChecks([]), MoveChecks([])])
    assert free.blends_mm[0] > r  # the post is what limits it
    assert chosen.duration_s < chosen.path.stopped_duration


def test_clearance_is_the_margin_at_which_the_collision_check_first_hits() -> None:
    from omnisort_hw.core.collision import FloorPlane, clearance, collision_mask

    planner, moves, _ = _corner()
    floor = FloorPlane(np.eye(4), "floor")
    obstacles = [POST, floor]
    for q in (moves[0].q_target, moves[1].q_target, Q0):
        gap = clearance(planner.model, q, obstacles, tool_capsules=planner.gripper)
        assert np.isfinite(gap) and gap > 0.0
        for margin, hit in ((gap - 0.01, False), (gap + 0.01, True)):
            got = collision_mask(
                planner.model, q[None], obstacles, tool_capsules=planner.gripper, margin_mm=margin
            )[0]
            assert got == hit, (q, gap, margin)
