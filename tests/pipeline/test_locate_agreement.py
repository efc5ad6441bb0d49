"""`omnisort locate` and the service's `locate` are one use case: on the same image and cell
file they give the same cubes (both read `[sorting]`, its floor height included)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pybullet", reason="the image is rendered by the simulated cell")

from omnisort_hw.cell.cell import Cell, CellDevices
from omnisort_hw.config.cell import load_cell_config
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.pipeline.requests import LocateRequest
from omnisort_hw.wire_records import to_wire
from tests.cli_json import cli_result
from tests.pipeline.registered_scene import registered_scene


def locate_cli(*args: str) -> dict:
    return cli_result("locate", *args)


def test_cli_and_service_locate_the_same_cubes(tmp_path: Path) -> None:
    rs = registered_scene(tmp_path, seed=4, laser_on=False)
    image_path, truth, store, system, floor = (
        rs.image_path,
        rs.truth,
        rs.store,
        rs.system,
        rs.floor_z_B_mm,
    )
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
    service = to_wire(cell.jobs.locate(LocateRequest(str(image_path))))
    reply = locate_cli(str(image_path), "--system", str(system), "--config", str(cell_file))
    # The whole answer: the cubes, their count, the blobs rejected with their reasons and the
    # verdict; each door writes its picture where it keeps them (state dir; beside the file).
    service_pic, cli_pic = Path(service.pop("overlay_png")), Path(reply.pop("overlay_png"))
    assert service_pic.is_file() and cli_pic.is_file() and service_pic != cli_pic
    assert json.loads(json.dumps(service)) == reply
    cli = reply["cubes"]
    # Not a vacuous agreement: every cube of the scene, where the truth has it.
    assert len(cli) == len(truth["cubes"]) >= 3
    for cube in truth["cubes"]:
        d = [np.linalg.norm(np.subtract(c["center_B_mm"], cube["center_B_mm"])) for c in cli]
        assert min(d) < 3.0, (cube, d)
    # The floor height matters: without the cell file the CLI puts the cubes elsewhere.
    plain = locate_cli(str(image_path), "--system", str(system))["cubes"]
    moved = [
        np.linalg.norm(np.subtract(a["center_B_mm"], b["center_B_mm"]))
        for a, b in zip(
            sorted(plain, key=lambda c: c["center_B_mm"]),
            sorted(cli, key=lambda c: c["center_B_mm"]),
            strict=True,
        )
    ]
    assert min(moved) > 1.0
