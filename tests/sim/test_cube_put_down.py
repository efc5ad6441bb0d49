"""A cube put down by hand (the Simulator tab's `cube` control) rests on what is under it: the
floor, or the floor board lying on it. Set into the board instead, the contact solver would
push it out over the next steps, so where it is reported would depend on when it is read."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pybullet")

from sim_backend.scene import load_scene
from sim_backend.sim_cell import SimCell

SLOP_MM = 0.2
"""A cube resting on a surface sinks into it by the contact's slop: under 0.07 mm in 600 steps
after a put-down at three spots (measured), so 0.2 mm."""


@pytest.mark.parametrize(("x_mm", "y_mm", "on"), [(0.0, 1000.0, "board"), (0.0, 560.0, "floor")])
def test_a_cube_put_down_rests_where_it_was_put(x_mm: float, y_mm: float, on: str) -> None:
    scene = load_scene("sorting")
    cell = SimCell(scene)
    try:
        world = cell.world
        board = scene.robot.floor_board
        assert board is not None
        below = world.floor_z + (board.thickness_mm if on == "board" else 0.0)
        cell.place_cube(0, x_mm, y_mm, 30.0)
        _, body = world.info.cubes[0]
        heights = []
        for _ in range(120):  # half a second of physics
            world.step(1)
            heights.append(world.body_pose(body)[2, 3])
        centre = world.body_pose(body)[:3, 3]
    finally:
        cell.close()
    assert np.allclose(centre[:2], [x_mm, y_mm], atol=0.05), centre
    # At rest from the first step: never above where it was put, never deeper than the slop.
    assert max(heights) <= below + 50.0 + 1e-6, max(heights) - below - 50.0
    assert min(heights) > below + 50.0 - SLOP_MM, min(heights) - below - 50.0
