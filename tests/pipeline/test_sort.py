"""Sorting through the pipeline: the calibration gate, a whole sort on the simulated cell
verified from the simulator's state (cubes in the right bins, no contact), and the service's
commands through the cell."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")

from omnisort_hw.config.cell import CellConfig
from omnisort_hw.core.cube_location import UNKNOWN
from omnisort_hw.errors import MotionRefusedError
from omnisort_hw.pipeline.calibration_source import (
    FileCalibration,
    MemoryCalibration,
    StoreCalibration,
)
from omnisort_hw.pipeline.requests import LocateRequest, RegisterRequest, SortRequest
from omnisort_hw.pipeline.sort import Sorter
from omnisort_hw.runlog import RunLog, entity_paths
from sim_backend.sort_harness import SimScene, SimVerifier, sim_registration_config, sim_sort_config
from tests.pipeline.sorting_scene import (
    WIDTH,
    T_SB_of,
    sorting_scene,
    spy_linear_targets,
    truth_payload,
)

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

    cell = SimCell.from_scene(sorting_scene(), width=320)
    devs = SimCamera(cell), SimLaserSwitch(cell), SimArm(cell)
    for d in devs:
        d.connect()
    yield cell, devs
    for d in devs:
        d.close()
    cell.close()


def test_missing_stale_or_unregistered_calibration_moves_nothing(
    small_cell: Any, tmp_path: Path
) -> None:
    from omnisort_hw.pipeline.calibration_store import CalibrationStore

    cell, (cam, laser, arm) = small_cell
    rec = _Recorder(arm)
    cfg = sim_sort_config(cell.scene)
    q0 = arm.joint_positions().copy()
    stale = tmp_path / "stale.json"
    payload = truth_payload(cell)
    payload["created"] = "2020-01-01T00:00:00+00:00"
    stale.write_text(json.dumps(payload))
    unregistered = tmp_path / "unregistered.json"
    unregistered.write_text(json.dumps(truth_payload(cell, robot_base=False)))
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


# ---- a whole sort on the simulated cell ----------------------------------------------------


def test_sort_a_small_scene_end_to_end(tmp_path: Path) -> None:
    """Two sortable cubes, an unknown colour, one outside the arm's workspace box and one out of
    reach: the two end in their bins with no contact; the others are reported and never
    approached (they have not moved, no TCP target came near them)."""
    from sim_backend.devices import SimArm, SimCamera, SimCell, SimLaserSwitch
    from sim_backend.scene import NAMED_COLORS, Color, CubeSpec

    def cube(color: str, xy: tuple[float, float], yaw: float) -> CubeSpec:
        return CubeSpec(Color(color, NAMED_COLORS[color]), 100.0, xy, yaw)

    scene = sorting_scene(
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
        targets = spy_linear_targets(arm)
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
            report = sorter.run(
                register=True, on_located=verifier.on_located, on_done=verifier.on_done
            )
        verifier.stop()
    finally:
        for d in (arm, laser, cam):
            d.close()
        after = {t.index: t.center_S for t in verifier.true_cubes()}
        cell.close()
    totals = report.totals()
    by_colour = {o.color: o for o in report.outcomes if o.color in ("red", "blue", UNKNOWN)}
    assert totals.collisions == 0, report.extra.collision_events
    assert by_colour["red"].in_right_bin and by_colour["blue"].in_right_bin
    assert totals.sorted_ok == 2 and totals.sorted == 2
    reasons = sorted(
        o.reason.split(":")[0].split(" (")[0] for o in report.outcomes if o.status == "skipped"
    )
    assert reasons == ["outside the workspace", "unknown colour", "unreachable"], reasons
    assert totals.mean_position_error_mm is not None and totals.mean_position_error_mm <= 2.0
    assert report.registration is not None
    T_est = np.asarray(report.registration["matrix"], float)
    from omnisort_hw.core.registration import pose_error

    # 960 px: the registration's 1-sigma is ~0.6 mm (test_registration checks 2 mm at 1280).
    assert pose_error(T_est, T_SB_of(scene))[0] <= 3.0
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
        T_BS = np.linalg.inv(T_SB_of(scene))
        p_B = T_BS[:3, :3] @ before[i] + T_BS[:3, 3]
        assert min(np.linalg.norm(t[:2] - p_B[:2]) for t in targets) > 150.0


def test_service_commands_through_the_cell(tmp_path: Path) -> None:
    """register_robot, locate and sort as the service runs them: the cell's devices and its
    calibration store (robot_base written there), on the simulated cell."""
    import threading

    from omnisort_hw.cell.cell import Cell, CellDevices
    from omnisort_hw.core.camera_io import camera_record
    from omnisort_hw.core.pick_planning import SortConfig
    from omnisort_hw.pipeline.calibration_store import CalibrationStore
    from sim_backend.devices import SimArm, SimCamera, SimCell, SimLaserSwitch
    from sim_backend.scene import NAMED_COLORS, Color, CubeSpec, load_scene, sized

    scene = sized(load_scene("sorting"), WIDTH).replace(
        robot={"home_deg": SortConfig().home_deg},
        cubes=(CubeSpec(Color("blue", NAMED_COLORS["blue"]), 100.0, (100.0, 620.0), 30.0),),
    )
    sim = SimCell(scene, seed=5)
    arm = SimArm(sim)
    devices = CellDevices(SimCamera(sim), SimLaserSwitch(sim), arm, SimScene(sim, arm))
    truth = truth_payload(sim)
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
    cell = Cell(devices, store, config=CellConfig.from_mapping(config))
    cell.connect()
    try:
        cancel = threading.Event()
        reg = cell.jobs.register_robot(RegisterRequest(), cancel)
        rb = store.load_system()["robot_base"]
        assert rb == json.loads(json.dumps(reg.robot_base))
        np.testing.assert_allclose(rb["xyz_mm"], truth["robot_base"]["xyz_mm"], atol=3.0)
        located = cell.jobs.locate(LocateRequest(), cancel)
        assert located.count == 1 and located.cubes[0].color == "blue"
        np.testing.assert_allclose(
            located.cubes[0].center_B_mm, truth["cubes"][0]["center_B_mm"], atol=3.0
        )
        result = cell.jobs.sort(SortRequest(), cancel)
        assert result.totals.sorted == 1, result
        verifier = SimVerifier(devices.arm)
        final = verifier.true_cubes()[0]
        assert verifier.bin_of(final.center_S) == "blue"
    finally:
        cell.close()
        sim.close()
