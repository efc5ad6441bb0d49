"""`omnisort check` and `omnisort extrinsics calibrate` are the service's drift check and
extrinsic calibration: on the same image, calibration and cell file they give the same result,
field for field (the service's reply and the CLI's `--json` result). A door that judged with
other settings (another board, another reference, no checksum check) would differ here."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import pytest

pytest.importorskip("pybullet", reason="the images are rendered by the simulated cell")

from omnisort_hw.cell.cell import Cell, CellDevices
from omnisort_hw.config.cell import CellConfig, load_cell_config
from omnisort_hw.core.camera_io import camera_record
from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.pipeline.calibration_store import CalibrationStore
from omnisort_hw.pipeline.drift_check import calibration_key, save_reference
from omnisort_hw.pipeline.requests import CalibrateRequest
from omnisort_hw.wire_records import to_wire
from tests.cli_json import cli_result

pytestmark = pytest.mark.timeout(600)


def cli(*args: str, ok_codes: tuple[int, ...] = (0,)) -> dict[str, Any]:
    return dict(cli_result(*args, ok_codes=ok_codes))


def as_json(obj: Any) -> Any:
    return json.loads(json.dumps(to_wire(obj)))


def test_cli_check_is_the_watchdogs_check(tmp_path: Path) -> None:
    from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
    from omnisort_hw.pipeline.registration import register_from_image, robot_base_record
    from sim_backend.devices import SimCell
    from sim_backend.sort_harness import sim_registration_config

    sim = SimCell.from_scene("sorting", seed=5, width=640, height=640)
    try:
        ref, truth = sim.render(1, True, laser_on=False, with_truth=True)
        same, _ = sim.render(2, True, laser_on=False)
        sim.bump_camera(0.2, "x")
        knocked, _ = sim.render(3, True, laser_on=False)
        rc = sim_registration_config(sim.scene)
    finally:
        sim.close()
    calib = SystemCalibration.from_json(truth, source="truth")
    reg = register_from_image(ref, calib, rc)
    store = CalibrationStore(state_dir=tmp_path / "state")
    store.save_camera(camera_record(OcamModel.from_dict(truth["camera"])))
    payload = {k: truth[k] for k in ("camera", "camera_rotation", "laser_plane", "target")}
    payload.update(method="truth", residuals={}, std={}, image=None, created="now")
    payload["robot_base"] = robot_base_record(reg, rc, "ref.png")
    system = store.save_system(payload)
    # The service's reference for this calibration, found by both doors beside system.json.
    save_reference(store.state_dir, ref, calibration_key(store.read("system").payload))
    # No [registration] in the cell file: both take the board the base was registered with.
    cell = Cell(CellDevices(), store, config=CellConfig())
    for name, img, code in (("same", same, 0), ("knocked", knocked, 4)):
        path = tmp_path / f"{name}.png"
        cv2.imwrite(str(path), img)
        service = as_json(cell.drift.check(str(path)))
        command = cli("check", str(path), "--system", str(system), ok_codes=(code,))
        # Everything but the clock's reading of when each check ran.
        assert command.pop("checked_at") and service.pop("checked_at")
        assert command == service
        assert command["drift"] is bool(code) and command["board"] is not None


def test_cli_calibrate_is_the_services_calibrate(tmp_path: Path) -> None:
    from sim_backend.scene import load_scene, sized
    from sim_backend.scene_images import render_scene

    scene = sized(load_scene("two_sided"), 960).replace(
        camera={"roll_deg": 3.0, "pitch_deg": -2.0, "yaw_deg": 5.0},
        laser={"roll_deg": -4.0, "pitch_deg": 4.0},
    )
    image, truth = render_scene(scene, seed=7)
    image_path = tmp_path / "target.png"
    cv2.imwrite(str(image_path), image)
    separation = truth["target"]["separation_mm"]
    store = CalibrationStore(state_dir=tmp_path / "state")
    camera = store.save_camera(camera_record(OcamModel.from_dict(truth["camera"])))
    cell_file = tmp_path / "cell.toml"
    cell_file.write_text(
        f'[storage]\nstate_dir = "{store.state_dir}"\n'
        f'[target]\nkind = "two-sided"\nseparation_mm = {separation}\n'
    )
    cell = Cell(CellDevices(), store, config=load_cell_config(cell_file))
    service = as_json(
        cell.jobs.calibrate_extrinsics(CalibrateRequest("extrinsics", image=str(image_path)))
    )
    out = tmp_path / "cli" / "system.json"
    command = cli(
        "extrinsics",
        "calibrate",
        str(image_path),
        "--camera",
        str(camera),
        "--target",
        "two-sided",
        "--separation",
        str(separation),
        "--out",
        str(out),
    )
    # One answer at both doors; only where each saved it (and its picture) differ.
    assert command.pop("path") == str(out) and service.pop("path") == str(store.path("system"))
    assert command.pop("overlay_png") and service.pop("overlay_png")
    assert command == service
    saved_cli = json.loads(out.read_text())
    saved_service = store.read("system").payload
    for key in ("camera_rotation", "laser_plane", "target", "method", "residuals", "std"):
        assert saved_cli[key] == as_json(saved_service[key]), key
    # Not a vacuous agreement: the calibration found the rendered laser plane.
    got, want = command["parameters"], truth["laser_plane"]
    assert got["laser_pitch_deg"] == pytest.approx(want["pitch_deg"], abs=0.05)
