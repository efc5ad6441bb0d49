"""The simulated sorting cell for fault tests: the demo's configuration, with the simulator's
true calibration written to the state directory (so no test spends minutes calibrating)."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

from omnisort_hw.cell import Cell
from omnisort_hw.service.config import Settings, load_settings
from omnisort_hw.service.demo import write_config
from omnisort_hw.storage import REQUIRED_KEYS

WIDTH = 320


def write_true_calibration(cell: Cell) -> None:
    """camera.json and system.json (with the robot base) from the simulator's truth."""
    cam = cell.devices.camera
    cam.grab(with_truth=True)
    truth = cam.last_truth
    assert truth is not None
    system = {k: truth[k] for k in ("camera", "camera_rotation", "laser_plane", "target")}
    system.update(
        method="truth",
        residuals={},
        std={},
        created=datetime.now(UTC).isoformat(timespec="seconds"),
        robot_base=truth["robot_base"],
    )
    assert all(k in system for k in REQUIRED_KEYS["system"])
    cell.store.save_camera(dict(truth["camera"]), camera_serial=cam.serial)
    cell.store.save_system(system, camera_serial=cam.serial)


def sim_settings(tmp: Path, width: int = WIDTH) -> Settings:
    """The demo's cell configuration for the simulated `sorting` scene, under `tmp`."""
    tmp.mkdir(parents=True, exist_ok=True)
    return load_settings(write_config(tmp, width))


def calibrated_sim_cell(tmp: Path, width: int = WIDTH) -> Cell:
    """A connected simulated cell with the true calibration in its state directory."""
    cell = Cell.from_settings(sim_settings(tmp, width))
    cell.connect()
    write_true_calibration(cell)
    cell.refresh_status()
    return cell
