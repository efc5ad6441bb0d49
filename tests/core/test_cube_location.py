"""Cube location: colour segmentation, silhouette fit on the top plane, laser refinement.

One render (laser off and on) of the sorting cell with the camera turned by a few degrees and
six cubes: red, green, blue, yellow, black and an orange one the default colour table does not
know. Positions compare with the simulator's truth; the tolerance is the issue's 2 mm mean
(the fit's own 1-sigma is ~0.3 mm at this size, an outline point's noise ~0.3 px).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")

from omnisort_hw.core.cube_location import (
    UNKNOWN,
    ColorTable,
    LocateSettings,
    locate_cubes,
    match_to_truth,
    silhouette,
)
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.errors import ConfigError, InputError

WIDTH = 960
REGION = (-520.0, 520.0, 110.0, 1190.0)
CUBES = (
    ("red", (-330.0, 560.0), 15.0),
    ("green", (-60.0, 520.0), 35.0),
    ("blue", (230.0, 580.0), 0.0),
    ("yellow", (-280.0, 790.0), 70.0),
    ("black", (330.0, 780.0), 50.0),
    ("orange", (0.0, 300.0), 25.0),
)


@pytest.fixture(scope="module")
def scene_images() -> dict[str, Any]:
    from sim_backend.scene import NAMED_COLORS, Color, CubeSpec, load_scene, sized
    from sim_backend.scene_images import render_scene

    base = sized(load_scene("sorting"), WIDTH)
    cubes = tuple(CubeSpec(Color(c, NAMED_COLORS[c]), 100.0, xy, yaw) for c, xy, yaw in CUBES)
    scene = base.replace(
        cubes=cubes,
        camera={"roll_deg": 4.0, "pitch_deg": -6.0, "yaw_deg": 7.0},
        robot={"home_deg": SortConfig().home_deg},
    )
    off, truth = render_scene(scene, seed=1, laser_on=False)
    on, _ = render_scene(scene, seed=1, laser_on=True, with_truth=False)
    assert truth is not None
    return {"off": off, "on": on, "truth": truth}


def _locate(data: dict[str, Any], laser: bool = False) -> tuple[list, dict]:
    from omnisort_hw.core.laser_stripe import laser_stripe_points
    from omnisort_hw.core.mapping import pixels_to_plane

    truth = data["truth"]
    calib = SystemCalibration.from_json(truth)
    T_SB = np.asarray(truth["robot_base"]["matrix"], float)
    lp = pixels_to_plane(laser_stripe_points(data["on"]), calib) if laser else None
    return locate_cubes(
        data["off"],
        calib.model,
        calib.R_SC,
        T_SB,
        settings=LocateSettings(region_S_mm=REGION),
        laser_points_S=lp,
    )


def _errors(cubes: list, truth: dict[str, Any]) -> tuple[list[float], list[float], list[float]]:
    true_S = np.array([c["center_S_mm"] for c in truth["cubes"]])
    idx = match_to_truth(cubes, true_S, max_mm=30.0)
    assert None not in idx, [c.summary() for c in cubes]
    pos, pos_B, yaw = [], [], []
    for c, k in zip(cubes, idx, strict=True):
        t = truth["cubes"][k]
        pos.append(float(np.linalg.norm(c.center_S - true_S[k])))
        pos_B.append(float(np.linalg.norm(c.center_B - np.asarray(t["center_B_mm"]))))
        d = (c.yaw_S_deg - t["yaw_deg"] + 45.0) % 90.0 - 45.0
        yaw.append(abs(d))
    return pos, pos_B, yaw


def test_cubes_found_with_their_colours(scene_images: dict[str, Any]) -> None:
    cubes, diag = _locate(scene_images)
    truth = scene_images["truth"]
    true_S = np.array([c["center_S_mm"] for c in truth["cubes"]])
    idx = match_to_truth(cubes, true_S, max_mm=30.0)
    assert len(cubes) == len(CUBES)
    for c, k in zip(cubes, idx, strict=True):
        assert k is not None
        expected = truth["cubes"][k]["colour"]
        assert c.color == (UNKNOWN if expected == "orange" else expected), c.summary()
    # The floor board's black squares, the bins and the walls are not cubes.
    assert any("area" in r.reason for r in diag["rejected"] if r.color == "black")


def test_cube_centres_and_yaw_against_truth(scene_images: dict[str, Any]) -> None:
    cubes, _ = _locate(scene_images)
    pos, pos_B, yaw = _errors(cubes, scene_images["truth"])
    assert np.mean(pos) <= 2.0, pos
    assert np.max(pos) <= 3.0, pos
    assert np.mean(pos_B) <= 2.0, pos_B
    assert np.max(yaw) <= 1.5, yaw
    for c in cubes:
        assert abs(c.center_B[2] - 50.0) < 0.5  # on the floor, half a cube up
        assert 0.02 < c.sigma_mm < 3.0, c.summary()
    # The reported 1-sigma is honest: most errors lie within 3 sigma.
    within = [e <= 3.0 * c.sigma_mm + 0.2 for e, c in zip(pos, cubes, strict=True)]
    assert sum(within) >= len(cubes) // 2, (pos, [c.sigma_mm for c in cubes])


def test_laser_refinement_keeps_the_accuracy(scene_images: dict[str, Any]) -> None:
    cubes, _ = _locate(scene_images, laser=True)
    pos, _, yaw = _errors(cubes, scene_images["truth"])
    assert np.mean(pos) <= 2.0, pos
    assert np.max(yaw) <= 1.5, yaw
    # Whatever the laser did for each cube, it is recorded: used points or a note why not.
    for c in cubes:
        assert c.laser_points >= 0
        assert all(isinstance(n, str) for n in c.notes)


def test_silhouette_is_the_hull_of_top_and_shrunk_bottom() -> None:
    hull = silhouette(np.array([500.0, 0.0]), 0.0, 50.0, 0.9)
    # The far edge (x = 550) belongs to the top face, the near edge is the bottom's at 0.9 x.
    assert hull[:, 0].max() == pytest.approx(550.0)
    assert hull[:, 0].min() == pytest.approx(0.9 * 450.0)
    assert len(hull) == 6


def test_colour_table_from_toml_and_its_errors(tmp_path: Path) -> None:
    path = tmp_path / "colors.toml"
    path.write_text(
        "[colors]\npurple = [[130, 160, 80, 255, 40, 255]]\nred = [0, 8, 100, 255, 50, 255]\n"
    )
    table = ColorTable.load(path)
    assert table.names() == ["purple", "red"]
    with pytest.raises(ConfigError, match="purple"):
        ColorTable.from_mapping({"purple": [[200, 100, 0, 255, 0, 255]]})
    with pytest.raises(ConfigError, match="reserved"):
        ColorTable.from_mapping({UNKNOWN: [0, 179, 0, 255, 0, 255]})
    with pytest.raises(ConfigError, match="not found"):
        ColorTable.load(tmp_path / "missing.toml")


def test_unusable_input_is_refused(scene_images: dict[str, Any]) -> None:
    truth = scene_images["truth"]
    calib = SystemCalibration.from_json(truth)
    T_SB = np.asarray(truth["robot_base"]["matrix"], float)
    with pytest.raises(InputError, match="camera model"):
        locate_cubes(scene_images["off"][:-2], calib.model, calib.R_SC, T_SB)
    with pytest.raises(InputError, match="8-bit BGR"):
        locate_cubes(scene_images["off"][..., 0], calib.model, calib.R_SC, T_SB)
