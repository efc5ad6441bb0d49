"""One rendered sorting scene on an 80 mm pedestal (so `[sorting] floor_z_B_mm` matters) and a
calibration store holding its true camera and registered system: what the agreement tests
feed to a command and to the service alike."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2

from omnisort_hw.core.camera_io import camera_record
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.pipeline.calibration_store import CalibrationStore

WIDTH = 960
CALIB_KEYS = ("camera", "camera_rotation", "laser_plane", "target", "robot_base")


@dataclass
class RegisteredScene:
    image_path: Path
    truth: dict[str, Any]
    store: CalibrationStore
    system: Path
    floor_z_B_mm: float


def registered_scene(tmp_path: Path, seed: int, laser_on: bool) -> RegisteredScene:
    from sim_backend.scene import load_scene, sized
    from sim_backend.scene_images import camera_model_for, render_scene
    from sim_backend.sort_harness import sim_sort_config

    scene = sized(load_scene("sorting"), WIDTH).replace(
        robot={"home_deg": SortConfig().home_deg, "pedestal_mm": 80.0}
    )
    image, truth = render_scene(scene, seed=seed, laser_on=laser_on)
    assert truth is not None and truth["robot_base"] is not None
    image_path = tmp_path / ("laser.png" if laser_on else "view.png")
    cv2.imwrite(str(image_path), image)
    store = CalibrationStore(state_dir=tmp_path / "state")
    store.save_camera(camera_record(camera_model_for(scene)))
    payload = {k: truth[k] for k in CALIB_KEYS}
    payload.update(method="truth", residuals={}, std={}, image=None, created="now")
    system = store.save_system(payload)
    return RegisteredScene(image_path, truth, store, system, sim_sort_config(scene).floor_z_B_mm)
