"""The simulated sorting scene and small builders shared by the sorting tests."""

from __future__ import annotations

from typing import Any

import numpy as np

from omnisort_hw.core.cube_location import Cube
from omnisort_hw.core.pick_planning import SortConfig

WIDTH = 960


def sorting_scene(**changes: Any) -> Any:
    from sim_backend.scene import load_scene, sized

    return sized(load_scene("sorting"), WIDTH).replace(
        robot={"home_deg": SortConfig().home_deg}, **changes
    )


def T_SB_of(scene: Any) -> np.ndarray:
    robot = scene.robot
    c, s = np.cos(np.radians(robot.base_yaw_deg)), np.sin(np.radians(robot.base_yaw_deg))
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = (*robot.base_mm, scene.floor_z)
    return T


def make_cube(color: str, xyz_B: tuple[float, float, float], yaw: float = 0.0) -> Cube:
    c = np.asarray(xyz_B, float)
    return Cube(color, c, c, yaw, yaw, (0.3, 0.3), 0.2, 0.3, 800, 100, 0, (0, 0, 0, 0))


def truth_payload(cell: Any, robot_base: bool = True) -> dict[str, Any]:
    from sim_backend.truth import build_truth

    truth = build_truth(cell.world, cell.model, False)
    if not robot_base:
        truth["robot_base"] = None
    return truth


def spy_linear_targets(arm: Any) -> list[np.ndarray]:
    """The TCP positions of every straight-line target the arm is sent (single moves and the
    linear waypoints of paths), filled in as the arm runs."""
    targets: list[np.ndarray] = []
    orig_linear, orig_path = arm.move_linear, arm.move_path

    def move_linear(pose: Any, *a: Any, **k: Any) -> None:
        targets.append(np.asarray(pose, float)[:3, 3].copy())
        orig_linear(pose, *a, **k)

    def move_path(path: Any, *a: Any, **k: Any) -> None:
        targets.extend(
            np.asarray(w.target, float)[:3, 3].copy() for w in path if w.kind == "linear"
        )
        orig_path(path, *a, **k)

    arm.move_linear, arm.move_path = move_linear, move_path
    return targets
