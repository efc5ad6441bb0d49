"""`omnisort map` and the service's `map` are one use case: on the same image, calibration and
cell file they give the same points (both judge the floor's mirror images against the floor of
`[sorting]` and the registered robot base). On this render the floor test drops no point that
the map's other echo rules keep, so the test guards the whole path's agreement rather than the
floor filter's own effect (that is `tests/core/test_laser_echoes.py`)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("pybullet", reason="the image is rendered by the simulated cell")

from omnisort_hw.cell.cell import Cell, CellDevices
from omnisort_hw.config.cell import load_cell_config
from omnisort_hw.pipeline.requests import MapRequest
from omnisort_hw.wire_records import to_wire
from tests.cli_json import cli_result
from tests.pipeline.registered_scene import registered_scene


def map_cli(*args: str) -> dict:
    return cli_result("map", *args, "--points")


def test_cli_and_service_map_the_same_points(tmp_path: Path) -> None:
    rs = registered_scene(tmp_path, seed=4, laser_on=True)
    store, image_path, system = rs.store, rs.image_path, rs.system
    cell_file = tmp_path / "cell.toml"
    cell_file.write_text(
        f'[storage]\nstate_dir = "{store.state_dir}"\n[sorting]\nfloor_z_B_mm = {rs.floor_z_B_mm}\n'
    )

    cell = Cell(CellDevices(), store, config=load_cell_config(cell_file))
    service = json.loads(
        json.dumps(to_wire(cell.jobs.map_scene(MapRequest(str(image_path), points=True))))
    )
    cli = map_cli(str(image_path), "--system", str(system), "--config", str(cell_file))
    assert cli["points_S"] == service["points_S"] and cli["pixels"] == service["pixels"]
    assert cli["segments"] == service["segments"]
    # Every point with its sigmas, the same in both.
    for key in ("sigma_normal_mm", "sigma_along_mm", "sigma_off_plane_mm"):
        assert cli[key] == service[key] and len(cli[key]) == len(cli["points_S"])
    assert min(cli["sigma_normal_mm"]) >= 0 and max(cli["sigma_normal_mm"]) > 0
    # Not a vacuous agreement: a real map of this scene.
    assert cli["points_on_plane"] > 50 and len(cli["segments"]) >= 3
