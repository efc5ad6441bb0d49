"""Sorting: configuration, planning and refusals, the calibration gate, and a whole sort on the
simulated cell verified from the simulator's state (cubes in the right bins, no contact)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")

from omnisort_hw.core.cube_location import UNKNOWN, Cube
from omnisort_hw.errors import ConfigError, MotionRefusedError
from omnisort_hw.runlog import RunLog, entity_paths
from omnisort_hw.sorting import (
    SUMMARY_KEYS,
    FileCalibration,
    MemoryCalibration,
    Planner,
    SimVerifier,
    SortConfig,
    Sorter,
    StoreCalibration,
    parse_registration_config,
    parse_sort_config,
    sim_registration_config,
    sim_sort_config,
    summarize_sorting,
)

WIDTH = 960


def _scene(**changes: Any) -> Any:
    from sim_backend.scene import load_scene, sized

    return sized(load_scene("sorting"), WIDTH).replace(
        robot={"home_deg": SortConfig().home_deg}, **changes
    )


def _T_SB(scene: Any) -> np.ndarray:
    robot = scene.robot
    c, s = np.cos(np.radians(robot.base_yaw_deg)), np.sin(np.radians(robot.base_yaw_deg))
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = (*robot.base_mm, scene.floor_z)
    return T


def _cube(color: str, xyz_B: tuple[float, float, float], yaw: float = 0.0) -> Cube:
    c = np.asarray(xyz_B, float)
    return Cube(color, c, c, yaw, yaw, (0.3, 0.3), 0.2, 0.3, 800, 100, 0, (0, 0, 0, 0))


# ---- configuration -------------------------------------------------------------------------


def test_config_sections_parse_and_name_bad_keys(tmp_path: Path) -> None:
    cfg = parse_sort_config(
        {
            "approach_mm": 120,
            "home_deg": [180, -70, -100, -100, 90, 90],
            "bins": [{"color": "red", "center_B_mm": [-100, -420]}],
            "obstacles": [
                {"name": "post", "frame": "S", "center_mm": [0, 0, -600], "size_mm": [50, 50, 1200]}
            ],
            "colors": {"red": [[0, 8, 100, 255, 50, 255]]},
        }
    )
    assert cfg.approach_mm == 120.0 and cfg.bin_for("red") is not None
    assert cfg.colors.names() == ["red"]
    with pytest.raises(ConfigError, match=r"\[sorting\]\.approach"):
        parse_sort_config({"approach": 1})
    with pytest.raises(ConfigError, match=r"home_deg"):
        parse_sort_config({"home_deg": [1, 2]})
    with pytest.raises(ConfigError, match=r"obstacles\[0\]\.frame"):
        parse_sort_config({"obstacles": [{"frame": "C"}]})
    reg = parse_registration_config(
        {"board": "9x6", "square_mm": 40, "offset": [200, -180, 2, 180, 0, 90]}
    )
    assert reg.board.cols == 9 and reg.fit == "auto"
    with pytest.raises(ConfigError, match=r"\[registration\]\.offset"):
        parse_registration_config({"square_mm": 40})


# ---- planning ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def planner() -> Planner:
    from drivers.base import MotionLimits

    scene = _scene()
    box = MotionLimits(workspace_min_mm=(-1100.0, -1100.0, 5.0), workspace_max_mm=(1100.0,) * 3)
    return Planner(sim_sort_config(scene), _T_SB(scene), workspace_check=box.check_position)


def test_reachable_cube_gives_a_checked_pick(planner: Planner) -> None:
    from omnisort_hw.core.kinematics import forward

    cube = _cube("red", (600.0, -150.0, 50.0), yaw=20.0)
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
        (_cube(UNKNOWN, (600.0, 0.0, 50.0)), "unknown colour"),
        (_cube("purple", (600.0, 0.0, 50.0)), "no bin configured"),
        (_cube("red", (1150.0, 0.0, 50.0)), "outside the workspace"),
        (_cube("red", (870.0, -420.0, 50.0)), "unreachable"),
    ],
)
def test_refused_cubes_get_no_moves(planner: Planner, cube: Cube, reason: str) -> None:
    plan = planner.plan_pick(cube, [], planner.home)
    assert plan.refused is not None and reason in plan.refused, plan.refused
    assert plan.moves == []


def test_neighbour_too_close_for_the_fingers(planner: Planner) -> None:
    a = _cube("red", (600.0, 0.0, 50.0), yaw=45.0)
    b = _cube("blue", (600.0, 115.0, 50.0), yaw=0.0)
    plan = planner.plan_pick(a, [b], planner.home)
    assert plan.refused is not None and plan.refused.startswith("no collision-free path")


# ---- the calibration gate: no motion at all ------------------------------------------------


class _Recorder:
    """Records every motion call made on a sim arm."""

    def __init__(self, arm: Any) -> None:
        self.calls: list[str] = []
        for name in ("move_joints", "move_linear"):
            orig = getattr(arm, name)

            def wrapped(*a: Any, _orig: Any = orig, _name: str = name, **k: Any) -> None:
                self.calls.append(_name)
                _orig(*a, **k)

            setattr(arm, name, wrapped)


@pytest.fixture
def small_cell() -> Any:
    from sim_backend.devices import SimArm, SimCamera, SimCell, SimLaserSwitch

    cell = SimCell.from_scene(_scene(), width=320)
    devs = SimCamera(cell), SimLaserSwitch(cell), SimArm(cell)
    for d in devs:
        d.connect()
    yield cell, devs
    for d in devs:
        d.close()
    cell.close()


def _truth_payload(cell: Any, robot_base: bool = True) -> dict[str, Any]:
    from sim_backend.truth import build_truth

    truth = build_truth(cell.world, cell.model, False)
    if not robot_base:
        truth["robot_base"] = None
    return truth


def test_missing_stale_or_unregistered_calibration_moves_nothing(
    small_cell: Any, tmp_path: Path
) -> None:
    from omnisort_hw.storage import CalibrationStore

    cell, (cam, laser, arm) = small_cell
    rec = _Recorder(arm)
    cfg = sim_sort_config(cell.scene)
    q0 = arm.joint_positions().copy()
    stale = tmp_path / "stale.json"
    payload = _truth_payload(cell)
    payload["created"] = "2020-01-01T00:00:00+00:00"
    stale.write_text(json.dumps(payload))
    unregistered = tmp_path / "unregistered.json"
    unregistered.write_text(json.dumps(_truth_payload(cell, robot_base=False)))
    corrupt = tmp_path / "corrupt.json"
    corrupt.write_text("{ not json")
    store = CalibrationStore(state_dir=tmp_path / "state")
    cases = [
        (FileCalibration(tmp_path / "missing.json"), "not found"),
        (FileCalibration(stale, max_age_days=30), "days old"),
        (FileCalibration(corrupt), "corrupt"),
        (FileCalibration(unregistered), "register the robot"),
        (StoreCalibration(store), "calibration not usable"),
    ]
    for source, message in cases:
        sorter = Sorter(cam, arm, laser, source, cfg)
        with pytest.raises(MotionRefusedError, match=message):
            sorter.run()
    assert rec.calls == []
    np.testing.assert_allclose(arm.joint_positions(), q0)


def test_collision_monitor_sees_a_crash(small_cell: Any) -> None:
    _, (_, _, arm) = small_cell
    verifier = SimVerifier(arm, check_every=1)
    verifier.start()
    try:
        # Sweep the arm down through the red bin and into the floor beside it.
        arm.move_joints([90.0, -30.0, 100.0, -70.0, 90.0, 0.0], speed_deg_s=180.0)
    finally:
        verifier.stop()
    hits = " ".join(verifier.collisions)
    assert "bin_0_red" in hits and "floor" in hits, verifier.collisions


# ---- a whole sort on the simulated cell ----------------------------------------------------


def test_sort_a_small_scene_end_to_end(tmp_path: Path) -> None:
    """Two sortable cubes, an unknown colour, one outside the arm's workspace box and one out of
    reach: the two end in their bins with no contact; the others are reported and never
    approached (they have not moved, no TCP target came near them)."""
    from sim_backend.devices import SimArm, SimCamera, SimCell, SimLaserSwitch
    from sim_backend.scene import NAMED_COLORS, Color, CubeSpec

    def cube(color: str, xy: tuple[float, float], yaw: float) -> CubeSpec:
        return CubeSpec(Color(color, NAMED_COLORS[color]), 100.0, xy, yaw)

    scene = _scene(
        cubes=(
            cube("red", (-250.0, 640.0), 20.0),
            cube("blue", (200.0, 700.0), -10.0),
            cube("orange", (0.0, 480.0), 30.0),
            cube("green", (0.0, 200.0), 0.0),
            cube("green", (-420.0, 470.0), 10.0),
        )
    )
    cell = SimCell(scene, seed=3)
    cam, laser, arm = SimCamera(cell), SimLaserSwitch(cell), SimArm(cell)
    for d in (cam, laser, arm):
        d.connect()
    try:
        targets: list[np.ndarray] = []
        orig_linear = arm.move_linear

        def move_linear(pose: Any, *a: Any, **k: Any) -> None:
            targets.append(np.asarray(pose, float)[:3, 3].copy())
            orig_linear(pose, *a, **k)

        arm.move_linear = move_linear  # type: ignore[method-assign]
        cam.grab(with_truth=True)
        from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration

        calib = SystemCalibration.from_json(cam.last_truth, source="truth")
        verifier = SimVerifier(arm)
        before = {t.index: t.center_S.copy() for t in verifier.true_cubes()}
        verifier.start()
        cfg = sim_sort_config(scene)
        with RunLog(tmp_path / "sort.rrd") as log:
            sorter = Sorter(
                cam, arm, laser, MemoryCalibration(calib), cfg, sim_registration_config(scene), log
            )
            report = sorter.run(register=True, verifier=verifier)
        verifier.stop()
    finally:
        for d in (arm, laser, cam):
            d.close()
        after = {t.index: t.center_S for t in verifier.true_cubes()}
        cell.close()
    totals = report.totals()
    by_colour = {o.color: o for o in report.outcomes if o.color in ("red", "blue", UNKNOWN)}
    assert totals["collisions"] == 0, report.extra["collision_events"]
    assert by_colour["red"].in_right_bin and by_colour["blue"].in_right_bin
    assert totals["sorted_ok"] == 2 and totals["sorted"] == 2
    reasons = sorted(
        o.reason.split(":")[0].split(" (")[0] for o in report.outcomes if o.status == "skipped"
    )
    assert reasons == ["outside the workspace", "unknown colour", "unreachable"], reasons
    assert totals["mean_position_error_mm"] <= 2.0
    assert report.registration is not None
    T_est = np.asarray(report.registration["matrix"], float)
    from omnisort_hw.core.registration import pose_error

    # 960 px: the registration's 1-sigma is ~0.6 mm (test_registration checks 2 mm at 1280).
    assert pose_error(T_est, _T_SB(scene))[0] <= 3.0
    logged = entity_paths(tmp_path / "sort.rrd")
    for entity in (
        "/registration/image/corners",
        "/registration/T_SB",
        "/sorting/masks/red",
        "/sorting/cubes_B",
        "/sorting/planned/tcp_path_B",
        "/sorting/executed/tcp_B",
    ):
        assert entity in logged, sorted(logged)
    untouched = [2, 3, 4]
    for i in untouched:
        assert np.linalg.norm(after[i] - before[i]) < 0.5, (i, before[i], after[i])
        T_BS = np.linalg.inv(_T_SB(scene))
        p_B = T_BS[:3, :3] @ before[i] + T_BS[:3, 3]
        assert min(np.linalg.norm(t[:2] - p_B[:2]) for t in targets) > 150.0


def test_evaluation_totals_have_the_documented_keys() -> None:
    rows = [
        {
            "scene": 0,
            "cubes": 3,
            "sorted_ok": 3,
            "collisions": 0,
            "position_errors_mm": [0.5, 1.0],
            "registration_error_mm": 0.4,
            "registration_error_deg": 0.01,
            "motion_s_per_pick": 9.0,
            "wall_s_per_pick": 3.0,
        },
        {
            "scene": 1,
            "cubes": 4,
            "sorted_ok": 3,
            "collisions": 1,
            "position_errors_mm": [1.5],
            "registration_error_mm": 0.6,
            "registration_error_deg": 0.02,
            "motion_s_per_pick": 10.0,
            "wall_s_per_pick": 4.0,
            "skipped": ["unreachable"],
        },
    ]
    out = summarize_sorting(rows, 12.0, 0, 960, "truth")
    # Every figure the CLI and the benchmark print.
    for key in (*SUMMARY_KEYS, "wall_s"):
        assert key in out, key
    assert out["cubes"] == 7 and out["sorted_ok"] == 6 and out["collisions"] == 1
    assert out["success_rate"] == pytest.approx(6 / 7, abs=1e-4)
    assert out["mean_position_error_mm"] == pytest.approx(1.0)
    assert out["not_sorted"][0]["scene"] == 1


def test_service_commands_through_the_cell(tmp_path: Path) -> None:
    """register_robot, locate and sort as the service runs them: the cell's devices and its
    calibration store (robot_base written there), on the simulated cell."""
    import threading

    from omnisort_hw.cell import Cell, CellDevices
    from omnisort_hw.core.camera_io import camera_record
    from omnisort_hw.storage import CalibrationStore
    from sim_backend.devices import SimArm, SimCamera, SimCell, SimLaserSwitch
    from sim_backend.scene import NAMED_COLORS, Color, CubeSpec, load_scene, sized

    scene = sized(load_scene("sorting"), WIDTH).replace(
        robot={"home_deg": SortConfig().home_deg},
        cubes=(CubeSpec(Color("blue", NAMED_COLORS["blue"]), 100.0, (100.0, 620.0), 30.0),),
    )
    sim = SimCell(scene, seed=5)
    devices = CellDevices(SimCamera(sim), SimLaserSwitch(sim), SimArm(sim))
    truth = _truth_payload(sim)
    store = CalibrationStore(state_dir=tmp_path / "state")
    serial = devices.camera.serial  # type: ignore[union-attr]
    store.save_camera(camera_record(sim.model), camera_serial=serial)
    payload = {k: truth[k] for k in ("camera", "camera_rotation", "laser_plane", "target")}
    payload.update(robot_base=None, method="truth", residuals={}, std={}, image=None, created="now")
    store.save_system(payload, camera_serial=serial)
    config = {
        "registration": {"board": "9x6", "square_mm": 40.0, "offset": [200, -180, 2, 180, 0, 90]},
        "sorting": {"from_scene": True},
    }
    cell = Cell(devices, store, config=config)
    cell.connect()
    try:
        cancel = threading.Event()
        reg = cell.register_robot(None, cancel)
        rb = store.load_system()["robot_base"]
        assert rb == json.loads(json.dumps(reg["robot_base"]))
        np.testing.assert_allclose(rb["xyz_mm"], truth["robot_base"]["xyz_mm"], atol=3.0)
        located = cell.locate(None, None, cancel)
        assert located["count"] == 1 and located["cubes"][0]["color"] == "blue"
        np.testing.assert_allclose(
            located["cubes"][0]["center_B_mm"], truth["cubes"][0]["center_B_mm"], atol=3.0
        )
        result = cell.sort(None, None, cancel)
        assert result["totals"]["sorted"] == 1, result
        verifier = SimVerifier(devices.arm)
        final = verifier.true_cubes()[0]
        assert verifier.bin_of(final.center_S) == "blue"
    finally:
        cell.close()
        sim.close()


def test_the_documented_cell_file_example_parses() -> None:
    import tomllib

    doc = SortConfig.__doc__ or ""
    block = "\n".join(line[8:] for line in doc.splitlines() if line.startswith("        "))
    data = tomllib.loads(block)
    cfg = parse_sort_config(data["sorting"])
    assert cfg.bin_for("red") is not None and cfg.obstacles[0].frame == "S"
    assert parse_registration_config(data["registration"]).offset[3] == 180.0


def test_example_cell_file_sorting_and_registration_sections_parse() -> None:
    """deploy/cell.example.toml documents [sorting] and [registration]; they must parse."""
    import tomllib
    from pathlib import Path

    from omnisort_hw.sorting import parse_registration_config, parse_sort_config

    example = Path(__file__).resolve().parents[2] / "deploy" / "cell.example.toml"
    data = tomllib.loads(example.read_text())
    cfg = parse_sort_config(data["sorting"])
    reg = parse_registration_config(data["registration"])
    assert cfg.robot_model == "UR5e" and cfg.bins and cfg.obstacles
    assert (reg.board.cols, reg.board.rows, reg.board.square_mm) == (9, 6, 40.0)
