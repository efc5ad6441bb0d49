"""`omnisort register-robot --json` prints exactly the service's `register_robot` reply: on the
same image and cell file, the same `robot_base` record, the same verdict, only the picture in
each door's own place (the CLI printed `{**record, "written"}`, the service `{"robot_base",
"path"}`)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pybullet", reason="the image is rendered by the simulated cell")

from omnisort_hw.cell.cell import Cell, CellDevices
from omnisort_hw.config.cell import load_cell_config
from omnisort_hw.pipeline.requests import RegisterRequest
from omnisort_hw.wire_records import to_wire
from tests.pipeline.registered_scene import registered_scene

pytestmark = pytest.mark.timeout(300)


def test_cli_and_service_register_the_same_base(tmp_path: Path) -> None:
    from omnisort_hw.core.pick_planning import SortConfig
    from sim_backend.scene import load_scene
    from sim_backend.sort_harness import sim_registration_config

    rs = registered_scene(tmp_path, seed=4, laser_on=False)
    # The board's pose in B as the scene has it (its robot stands on an 80 mm pedestal).
    scene = load_scene("sorting").replace(
        robot={"home_deg": SortConfig().home_deg, "pedestal_mm": 80.0}
    )
    rc = sim_registration_config(scene)
    cell_file = tmp_path / "cell.toml"
    cell_file.write_text(
        f'[storage]\nstate_dir = "{rs.store.state_dir}"\n'
        f'[registration]\nboard = "{rc.board.cols}x{rc.board.rows}"\n'
        f"square_mm = {rc.board.square_mm}\noffset = {list(rc.offset)}\n"
        f"camera_height_mm = {rc.camera_height_mm}\n"
    )
    cell = Cell(CellDevices(), rs.store, config=load_cell_config(cell_file))
    image = str(rs.image_path)
    service = json.loads(
        json.dumps(to_wire(cell.jobs.register_robot(RegisterRequest(image, save=False))))
    )
    cmd = [sys.executable, "-m", "omnisort_hw.cli", "register-robot", image]
    cmd += ["--system", str(rs.system), "--config", str(cell_file), "--no-save", "--json"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    cli = json.loads(proc.stdout)["result"]
    service_pic, cli_pic = Path(service.pop("overlay_png")), Path(cli.pop("overlay_png"))
    assert service_pic.is_file() and cli_pic.is_file()
    assert cli == service
    assert cli["path"] is None and cli["verdict"]["level"] == "pass", cli["verdict"]
    # Not a vacuous agreement: the base where the simulator put it.
    T = np.asarray(cli["robot_base"]["matrix"])
    T_true = np.asarray(rs.truth["robot_base"]["matrix"])
    assert np.linalg.norm(T[:3, 3] - T_true[:3, 3]) < 5.0
