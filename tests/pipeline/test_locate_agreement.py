"""`omnisort locate` and the service's `locate` are one use case: on the same image and cell
file they give the same cubes (both read `[sorting]`, its floor height included)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

pytest.importorskip("pybullet", reason="the image is rendered by the simulated cell")

from omnisort_hw.cell import Cell, CellDevices
from omnisort_hw.config.cell import load_cell_config
from omnisort_hw.core.camera_io import camera_record
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.storage import CalibrationStore

WIDTH = 960
CALIB_KEYS = ("camera", "camera_rotation", "laser_plane", "target", "robot_base")


def locate_cli(*args: str) -> list[dict]:
    proc = subprocess.run(
        [sys.executable, "-m", "omnisort_hw.cli", "locate", *args, "--json"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)["result"]["cubes"]


def test_cli_and_service_locate_the_same_cubes(tmp_path: Path) -> None:
    from sim_backend.scene import load_scene, sized
    from sim_backend.scene_images import camera_model_for, render_scene
    from sim_backend.sort_harness import sim_sort_config

    # On an 80 mm pedestal: the floor is below the base, so [sorting] floor_z_B_mm matters.
    scene = sized(load_scene("sorting"), WIDTH).replace(
        robot={"home_deg": SortConfig().home_deg, "pedestal_mm": 80.0}
    )
    image, truth = render_scene(scene, seed=4, laser_on=False)
    assert truth is not None and truth["robot_base"] is not None
    image_path = tmp_path / "view.png"
    cv2.imwrite(str(image_path), image)
    store = CalibrationStore(state_dir=tmp_path / "state")
    store.save_camera(camera_record(camera_model_for(scene)))
    payload = {k: truth[k] for k in CALIB_KEYS}
    payload.update(method="truth", residuals={}, std={}, image=None, created="now")
    system = store.save_system(payload)
    floor = sim_sort_config(scene).floor_z_B_mm
    assert floor == -80.0
    (tmp_path / "conf").mkdir()
    (tmp_path / "conf" / "colours.toml").write_text(
        "[colors]\n"
        + "\n".join(
            f"{name} = {[list(r) for r in rows]}"
            for name, rows in SortConfig().colors.ranges.items()
        )
        + "\n"
    )
    cell_file = tmp_path / "conf" / "cell.toml"
    cell_file.write_text(
        f'[storage]\nstate_dir = "{store.state_dir}"\n'
        f"[sorting]\ncube_size_mm = 100\nfloor_z_B_mm = {floor}\nuse_laser = false\n"
        'colors_file = "colours.toml"\n'
    )

    cell = Cell(CellDevices(), store, config=load_cell_config(cell_file))
    service = cell.locate(str(image_path), None)
    cli = locate_cli(str(image_path), "--system", str(system), "--config", str(cell_file))
    assert service["cubes"] == json.loads(json.dumps(cli))
    # Not a vacuous agreement: every cube of the scene, where the truth has it.
    assert len(cli) == len(truth["cubes"]) >= 3
    for cube in truth["cubes"]:
        d = [np.linalg.norm(np.subtract(c["center_B_mm"], cube["center_B_mm"])) for c in cli]
        assert min(d) < 3.0, (cube, d)
    # The floor height matters: without the cell file the CLI puts the cubes elsewhere.
    plain = locate_cli(str(image_path), "--system", str(system))
    moved = [
        np.linalg.norm(np.subtract(a["center_B_mm"], b["center_B_mm"]))
        for a, b in zip(
            sorted(plain, key=lambda c: c["center_B_mm"]),
            sorted(cli, key=lambda c: c["center_B_mm"]),
            strict=True,
        )
    ]
    assert min(moved) > 1.0
