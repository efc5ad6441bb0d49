"""`omnisort sort` passes the service's gates before it connects a device: a drift of the
calibration on record in the cell's state folder refuses it with the service's
`calibration_drift`, and a tampered store file with its `motion_refused`."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest

from omnisort_hw.cli import main
from omnisort_hw.core.camera_io import camera_record
from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.pipeline.calibration_store import CalibrationStore
from omnisort_hw.pipeline.drift_check import DRIFT_STATE_NAME, calibration_key

pytest.importorskip("pybullet", reason="the cell file's devices are the simulated ones")
ROOT = Path(__file__).resolve().parents[2]
SIM_SERIAL = "SIM-sorting-960x960-equidistant185"


def _cell(tmp_path: Path) -> tuple[Path, CalibrationStore]:
    """The shipped simulated cell file with its state and logs in `tmp_path`, and a store
    holding a calibration (a level camera, the laser 950 mm below it)."""
    text = (ROOT / "deploy" / "cell.sim.toml").read_text()
    text = re.sub(r'state_dir = ".*"', f'state_dir = "{tmp_path / "state"}"', text)
    text = re.sub(r'log_dir = ".*"', f'log_dir = "{tmp_path / "logs"}"', text)
    cfg = tmp_path / "cell.toml"
    cfg.write_text(text)
    # made with the shipped cell's (simulated) camera, as its service would have stored it
    store = CalibrationStore(state_dir=tmp_path / "state", expected_serial=SIM_SERIAL)
    model = OcamModel.equidistant(960, 960, 185.0)
    store.save_camera(camera_record(model))
    zero = dict.fromkeys(
        ("cam_roll_deg", "cam_pitch_deg", "cam_yaw_deg", "laser_roll_deg", "laser_pitch_deg"), 0.0
    )
    calib = SystemCalibration.from_angles(model, {**zero, "laser_distance_mm": 950.0}, "truth")
    store.save_system(
        {
            **calib.to_json(),
            "robot_base": {"matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]},
        }
    )
    return cfg, store


def service_refusal(cfg: Path, request: Any = None) -> dict[str, str]:
    """The error the service's cell raises for a sort on the same cell file and state."""
    import threading

    from omnisort_hw.cell.cell import Cell
    from omnisort_hw.config.cell import load_cell_config
    from omnisort_hw.errors import OmnisortError
    from omnisort_hw.pipeline.requests import SortRequest

    cell = Cell.from_settings(load_cell_config(cfg))
    cell.connect()
    try:
        cell.jobs.sort(request or SortRequest(), threading.Event())
    except OmnisortError as exc:
        return {"code": exc.code, "message": str(exc)}
    finally:
        cell.close()
    raise AssertionError("the service's cell sorted on a refused calibration")


def test_a_drift_on_record_refuses_the_cli_sort(tmp_path: Path, capsys) -> None:
    cfg, store = _cell(tmp_path)
    key = calibration_key(store.read("system").payload)
    drift = {"calibration_key": key, "angle_deg": 0.4, "threshold_deg": 0.1, "checked_at": "now"}
    (store.state_dir / DRIFT_STATE_NAME).write_text(json.dumps({"drift_detected": drift}))
    code = main(["sort", "--config", str(cfg), "--json"])
    err = json.loads(capsys.readouterr().out)["error"]
    assert code == 2 and err["code"] == "calibration_drift", err
    assert "0.400 deg" in err["message"] and "acknowledge_drift" in err["message"]
    assert service_refusal(cfg) == err
    # Acknowledged by an operator (as the service's acknowledge_drift records it): not refused
    # by the drift gate any more (what follows is the sort itself).
    ack = {"drift_detected": drift, "acknowledged": {"at": "now", "angle_deg": 0.4}}
    (store.state_dir / DRIFT_STATE_NAME).write_text(json.dumps(ack))
    from omnisort_hw.cli.file_rig import FileRig

    FileRig(config=cfg).check_drift()


def test_a_colour_with_no_bin_refuses_the_sort_before_anything_moves(
    tmp_path: Path, capsys
) -> None:
    """Every cube would be skipped: refused with the field and the cell's bins, by both doors
    (the service's before its gates, so on a good calibration too)."""
    from omnisort_hw.pipeline.requests import SortRequest

    cfg, _ = _cell(tmp_path)
    code = main(["sort", "--config", str(cfg), "--colors", "red,purple", "--json"])
    err = json.loads(capsys.readouterr().out)["error"]
    assert code == 2 and err["code"] == "bad_input", err
    assert "'colors': no bin for purple" in err["message"] and "red" in err["message"], err
    assert service_refusal(cfg, SortRequest(colors=("red", "purple"))) == err


def test_a_tampered_calibration_refuses_the_cli_sort(tmp_path: Path, capsys) -> None:
    cfg, store = _cell(tmp_path)
    path = store.path("system")
    doc = json.loads(path.read_text())
    doc["laser_plane"]["distance_mm"] = 900.0
    path.write_text(json.dumps(doc))
    code = main(["sort", "--config", str(cfg), "--json"])
    err = json.loads(capsys.readouterr().out)["error"]
    assert code == 2 and err["code"] == "motion_refused", err
    assert "checksum mismatch" in err["message"], err
    assert service_refusal(cfg) == err


def test_the_cli_sort_does_not_run_beside_the_service_of_the_same_cell(
    tmp_path: Path, capsys
) -> None:
    """The service holds STATE_DIR/omnisort.lock; a command-line sort of that cell is
    refused with instance_locked instead of driving the arm beside it."""
    from omnisort_hw.cell.lock import InstanceLock

    cfg, store = _cell(tmp_path)
    with InstanceLock(store.state_dir):
        code = main(["sort", "--config", str(cfg), "--json"])
    err = json.loads(capsys.readouterr().out)["error"]
    assert code == 2 and err["code"] == "instance_locked", err
