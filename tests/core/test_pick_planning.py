"""Pick planning (pure): a reachable cube gets a checked pick; refused cubes get no moves."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")

from omnisort_hw.core.cube_location import UNKNOWN, Cube
from omnisort_hw.core.pick_planning import Planner
from sim_backend.sort_harness import sim_sort_config
from tests.pipeline.sorting_scene import T_SB_of, make_cube, sorting_scene


@pytest.fixture(scope="module")
def planner() -> Planner:
    from drivers.base import MotionLimits

    scene = sorting_scene()
    box = MotionLimits(workspace_min_mm=(-1100.0, -1100.0, 5.0), workspace_max_mm=(1100.0,) * 3)
    return Planner(sim_sort_config(scene), T_SB_of(scene), workspace_check=box.check_position)


def test_reachable_cube_gives_a_checked_pick(planner: Planner) -> None:
    from omnisort_hw.core.kinematics import forward

    cube = make_cube("red", (600.0, -150.0, 50.0), yaw=20.0)
    plan = planner.plan_pick(cube, [], planner.home)
    assert plan.refused is None, plan.refused
    np.testing.assert_allclose(plan.moves[0].traj.q[0], planner.home)
    np.testing.assert_allclose(plan.moves[-1].q_target, planner.home)
    assert plan.descend is not None
    T = forward(planner.model, plan.descend.q_target, planner.tool)
    np.testing.assert_allclose(T[:3, 3], [600.0, -150.0, 58.0], atol=1e-6)
    np.testing.assert_allclose(T[:3, 2], [0.0, 0.0, -1.0], atol=1e-9)
    # Fingers close square to the cube's faces.
    yaw = np.degrees(np.arctan2(T[1, 0], T[0, 0]))
    assert abs((yaw - 20.0 + 45.0) % 90.0 - 45.0) < 1e-6
    # Consecutive moves join.
    for a, b in zip(plan.moves, plan.moves[1:], strict=False):
        np.testing.assert_allclose(a.traj.q[-1], b.traj.q[0], atol=1e-6)


@pytest.mark.parametrize(
    ("cube", "reason"),
    [
        (make_cube(UNKNOWN, (600.0, 0.0, 50.0)), "unknown colour"),
        (make_cube("purple", (600.0, 0.0, 50.0)), "no bin configured"),
        (make_cube("red", (1150.0, 0.0, 50.0)), "outside the workspace"),
        (make_cube("red", (870.0, -420.0, 50.0)), "unreachable"),
    ],
)
def test_refused_cubes_get_no_moves(planner: Planner, cube: Cube, reason: str) -> None:
    plan = planner.plan_pick(cube, [], planner.home)
    assert plan.refused is not None and reason in plan.refused, plan.refused
    assert plan.moves == []


def test_neighbour_too_close_for_the_fingers(planner: Planner) -> None:
    a = make_cube("red", (600.0, 0.0, 50.0), yaw=45.0)
    b = make_cube("blue", (600.0, 115.0, 50.0), yaw=0.0)
    plan = planner.plan_pick(a, [b], planner.home)
    assert plan.refused is not None and plan.refused.startswith("no collision-free path")
