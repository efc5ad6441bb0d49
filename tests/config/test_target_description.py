"""The target description file: the example in deploy/ loads, a generated file reads back to
the same layout, and every missing, misspelt, mistyped or implausible field is a ConfigError
naming the file and the field."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

from omnisort_hw.config.target import (
    load_target_description,
    parse_target_description,
    target_description_toml,
)
from omnisort_hw.errors import ConfigError

EXAMPLE = Path(__file__).resolve().parents[2] / "deploy" / "target.example.toml"


def _doc() -> dict:
    return tomllib.loads(EXAMPLE.read_text(encoding="utf-8"))


def test_example_loads() -> None:
    layout = load_target_description(EXAMPLE)
    assert layout.kind == "two-sided"
    assert layout.separation_mm == pytest.approx(1292.4)
    assert set(layout.walls) == {"left", "right"}
    assert layout.walls["right"].markers["border_near"].size_mm == (42.7, 51.0)
    assert layout.border_offset_mm("right") == 0.0


def test_round_trip(tmp_path: Path) -> None:
    layout = load_target_description(EXAMPLE)
    path = tmp_path / "t.toml"
    path.write_text(target_description_toml(layout), encoding="utf-8")
    again = load_target_description(path)
    assert again.walls == layout.walls and again.separation_mm == layout.separation_mm


def _drop(doc: dict, keys: tuple[str, ...]) -> dict:
    node = doc
    for k in keys[:-1]:
        node = node[k]
    del node[keys[-1]]
    return doc


def _set(doc: dict, keys: tuple[str, ...], value: object) -> dict:
    node = doc
    for k in keys[:-1]:
        node = node[k]
    node[keys[-1]] = value
    return doc


@pytest.mark.parametrize(
    ("keys", "field"),
    [
        (("separation_mm",), "target.separation_mm: missing"),
        (("walls", "right"), "walls.right: missing"),
        (("walls", "left", "border_height_mm"), "walls.left.border_height_mm: missing"),
        (("walls", "left", "markers", "floor_far"), "walls.left.markers.floor_far: missing"),
        (
            ("walls", "right", "markers", "border_near", "along_mm"),
            "walls.right.markers.border_near.along_mm: missing",
        ),
    ],
)
def test_missing_field_is_named(keys: tuple[str, ...], field: str) -> None:
    with pytest.raises(ConfigError, match="^" + re.escape(f"t.toml: {field}")):
        parse_target_description(_drop(_doc(), keys), "t.toml")


@pytest.mark.parametrize(
    ("keys", "value", "field"),
    [
        (("kind",), "four-sided", "target.kind"),
        (("separation_mm",), 1.2924, "target.separation_mm: 1.2924 looks like metres"),
        (("separation_mm",), "1292", "target.separation_mm"),
        (("walls", "left", "border_height_mm"), True, "walls.left.border_height_mm"),
        (("walls", "left", "border_height_mm"), -5.0, "walls.left.border_height_mm"),
        (
            ("walls", "left", "markers", "border_far", "height_mm"),
            float("nan"),
            "walls.left.markers.border_far.height_mm",
        ),
        (
            ("walls", "right", "markers", "floor_near", "size_mm"),
            [49.4],
            "walls.right.markers.floor_near.size_mm",
        ),
        (("walls", "left", "markers"), [1, 2], "walls.left.markers: expected a table"),
        (("walls", "left", "colour"), "white", "walls.left.colour: unknown key"),
        (("walls", "left", "markers", "top_near"), {}, "walls.left.markers.top_near: unknown"),
        (("walls", "far"), {}, "target.walls.far: unknown key"),
    ],
)
def test_wrong_field_is_named(keys: tuple[str, ...], value: object, field: str) -> None:
    with pytest.raises(ConfigError, match="^" + re.escape(f"t.toml: {field}")):
        parse_target_description(_set(_doc(), keys, value), "t.toml")


def test_file_errors_are_typed(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not found"):
        load_target_description(tmp_path / "absent.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("kind = \n", encoding="utf-8")
    with pytest.raises(ConfigError, match=re.escape("bad.toml: not valid TOML")):
        load_target_description(bad)
