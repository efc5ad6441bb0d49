"""Scene files: the shipped scenes load; bad files are clear errors naming the field."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from omnisort_hw.errors import ConfigError
from sim_backend.scene import SCENES_DIR, load_scene, scene_from_dict, shipped_scenes


def _data(name: str = "two_sided") -> dict:
    return tomllib.loads((SCENES_DIR / f"{name}.toml").read_text())


def test_shipped_scenes_load() -> None:
    assert set(shipped_scenes()) >= {"two_sided", "three_sided", "checkerboards", "sorting"}
    for name in shipped_scenes():
        scene = load_scene(name)
        assert scene.name == name
    sorting = load_scene("sorting")
    assert sorting.robot is not None and sorting.robot.floor_board is not None
    assert len(sorting.cubes) == 4 and len(sorting.bins) == 4
    assert load_scene("two_sided").target.separation_mm == pytest.approx(1084.5)


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda d: d["target"].update(colour="red"), "target.colour"),
        (lambda d: d.update(lights={}), "lights"),
        (lambda d: d["scene"].pop("name"), "scene.name"),
        (lambda d: d["target"].pop("kind"), "target.kind"),
        (lambda d: d["target"].update(separation_mm=-5.0), "target.separation_mm"),
        (lambda d: d["target"].update(separation_mm="wide"), "target.separation_mm"),
        (lambda d: d["target"].update(marker_inset_mm=600.0), "target.marker_inset_mm"),
        (lambda d: d["target"].update(border_height_mm=1200.0), "target.border_height_mm"),
        (lambda d: d["target"].update(marker_low_mm=740.0), "target.marker_low_mm"),
        (lambda d: d["laser"].update(distance_mm=0.0), "laser.distance_mm"),
        (lambda d: d["laser"].update(distance_mm=1300.0), "laser.distance_mm"),
        (lambda d: d["camera"].update(width=-1), "camera.width"),
        (
            lambda d: d.update(
                cubes=[{"color": "red", "size_mm": 100.0, "position_mm": [-560.0, 600.0]}]
            ),
            "cubes[0].position_mm",
        ),
        (lambda d: d.update(cubes=[{"color": "red", "size_mm": 100.0}]), "cubes[0].position_mm"),
        (
            lambda d: d.update(
                cubes=[{"color": "mauve", "size_mm": 50.0, "position_mm": [0.0, 0.0]}]
            ),
            "cubes[0].color",
        ),
        (lambda d: d.update(robot={"model": "UR7"}), "robot.model"),
    ],
)
def test_bad_scene_names_the_field(edit, field: str) -> None:
    data = _data()
    edit(data)
    with pytest.raises(ConfigError) as info:
        scene_from_dict(data, source="test.toml")
    message = str(info.value)
    assert field in message, message
    assert message.startswith("scene test.toml: ")


def test_board_right_must_be_perpendicular() -> None:
    data = _data("checkerboards")
    data["checkerboards"][1]["right"] = [1.0, -1.0, 0.0]
    with pytest.raises(ConfigError, match=r"checkerboards\[1\]\.right"):
        scene_from_dict(data)


def test_missing_file_and_bad_toml_are_config_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not found"):
        load_scene(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[scene\nname = 1")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_scene(bad)


def test_replace_validates_like_a_file() -> None:
    scene = load_scene("two_sided")
    tilted = scene.replace(camera={"roll_deg": 4.0}, laser={"pitch_deg": -3.0})
    assert tilted.camera.roll_deg == 4.0 and tilted.laser.pitch_deg == -3.0
    assert tilted.target == scene.target
    with pytest.raises(ConfigError, match=r"laser\.distance_mm"):
        scene.replace(laser={"distance_mm": -1.0})
