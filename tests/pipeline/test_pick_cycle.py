"""The pick cycle on the simulated cell: bin -> next cube without a return home, the next pick
planned while the arm moves, and the cycle's time accounted on the arm's clock."""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import pytest

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")

from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.pick_planning import Planner, SortConfig
from omnisort_hw.pipeline.calibration_source import MemoryCalibration
from omnisort_hw.pipeline.sort import Sorter
from sim_backend.sort_harness import SimVerifier, sim_sort_config
from tests.pipeline.sorting_scene import sorting_scene


def test_picks_chain_bin_to_cube_and_plan_ahead_while_the_arm_moves(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Three cubes: all in their bins with no contact; the arm visits home only at the end;
    every pick after the first was planned on the plan-ahead thread while the previous one
    moved; the cycle's motion is what the arm's clock counted and at least the plan's time."""
    from sim_backend.devices import SimArm, SimCamera, SimCell, SimLaserSwitch
    from sim_backend.scene import NAMED_COLORS, Color, CubeSpec

    def cube(color: str, xy: tuple[float, float], yaw: float) -> CubeSpec:
        return CubeSpec(Color(color, NAMED_COLORS[color]), 100.0, xy, yaw)

    scene = sorting_scene(
        cubes=(
            cube("red", (-250.0, 640.0), 20.0),
            cube("blue", (200.0, 700.0), -10.0),
            cube("green", (0.0, 560.0), 40.0),
        )
    )
    threads: list[str] = []
    orig_plan = Planner.plan_pick

    def plan_pick(self: Planner, *a: Any, **k: Any) -> Any:
        threads.append(threading.current_thread().name)
        return orig_plan(self, *a, **k)

    monkeypatch.setattr(Planner, "plan_pick", plan_pick)
    cell = SimCell(scene, seed=5)
    cam, laser, arm = SimCamera(cell), SimLaserSwitch(cell), SimArm(cell)
    for d in (cam, laser, arm):
        d.connect()
    targets: list[np.ndarray] = []
    orig_joints = arm.move_joints

    def move_joints(q: Any, *a: Any, **k: Any) -> None:
        targets.append(np.asarray(q, float).copy())
        orig_joints(q, *a, **k)

    arm.move_joints = move_joints  # type: ignore[method-assign]
    try:
        cam.grab(with_truth=True)
        calib = SystemCalibration.from_json(cam.last_truth, source="truth")
        verifier = SimVerifier(arm)
        verifier.start()
        cfg = sim_sort_config(scene)
        sorter = Sorter(
            cam,
            arm,
            laser,
            MemoryCalibration(calib),
            cfg,
            clock=lambda: cell.world.sim_time,
        )
        report = sorter.run(on_located=verifier.on_located, on_done=verifier.on_done)
        verifier.stop()
    finally:
        for d in (arm, laser, cam):
            d.close()
        cell.close()
    totals = report.totals()
    assert totals.collisions == 0, report.extra.collision_events
    assert totals.sorted == 3 and totals.sorted_ok == 3
    home = np.asarray(SortConfig().home_deg)
    at_home = [bool(np.max(np.abs(t - home)) < 0.5) for t in targets]
    assert at_home[-1] and not any(at_home[:-1]), at_home
    # The first plan is made before any motion; the next ones while the arm moves.
    assert threads[0] == threading.main_thread().name
    ahead = [t for t in threads[1:] if t.startswith("plan-ahead")]
    assert len(ahead) >= 2, threads
    cycle = report.extra.cycle
    assert cycle is not None
    assert cycle["picks"] == 3 and cycle["plans"] >= 3
    # Motion on the arm's clock: the sim arm re-plans each move at its 240 Hz step (a move can
    # end up to one step of each rate later than planned), so it is never shorter than the
    # plan by more than one planner sample per move.
    n_moves = len(targets) + 6  # joint moves counted; linear moves: 2 per pick
    assert cycle["motion_s"] >= cycle["planned_s"] - n_moves / 125.0
    # Gripper: one close and one open per pick, 0.2 s of physics each (never re-opened).
    assert cycle["gripper_s"] == pytest.approx(3 * 0.4, abs=3 * 2 / 240.0)
    expected = 60.0 / ((cycle["motion_s"] + cycle["gripper_s"] + cycle["wait_s"]) / 3)
    assert cycle["picks_per_minute"] == pytest.approx(expected, rel=1e-3)
