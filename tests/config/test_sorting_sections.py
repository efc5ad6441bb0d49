"""`[sorting]` and `[registration]`: parsed once, bad keys named, documented examples parse."""

from __future__ import annotations

from pathlib import Path

import pytest

from omnisort_hw.config.sorting import parse_registration_config, parse_sort_config
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.errors import ConfigError


def test_config_sections_parse_and_name_bad_keys(tmp_path: Path) -> None:
    cfg = parse_sort_config(
        {
            "approach_mm": 120,
            "home_deg": [180, -70, -100, -100, 90, 90],
            "bins": [{"color": "red", "center_B_mm": [-100, -420]}],
            "obstacles": [
                {"name": "post", "frame": "S", "center_mm": [0, 0, -600], "size_mm": [50, 50, 1200]}
            ],
            "colors": {"red": [[0, 8, 100, 255, 50, 255]]},
        }
    )
    assert cfg.approach_mm == 120.0 and cfg.bin_for("red") is not None
    assert cfg.colors.names() == ["red"]
    with pytest.raises(ConfigError, match=r"\[sorting\]\.approach"):
        parse_sort_config({"approach": 1})
    with pytest.raises(ConfigError, match=r"home_deg"):
        parse_sort_config({"home_deg": [1, 2]})
    with pytest.raises(ConfigError, match=r"obstacles\[0\]\.frame"):
        parse_sort_config({"obstacles": [{"frame": "C"}]})
    reg = parse_registration_config(
        {"board": "9x6", "square_mm": 40, "offset": [200, -180, 2, 180, 0, 90]}
    )
    assert reg.board.cols == 9 and reg.fit == "auto"
    with pytest.raises(ConfigError, match=r"\[registration\]\.offset"):
        parse_registration_config({"square_mm": 40})


def test_the_documented_cell_file_example_parses() -> None:
    import tomllib

    doc = SortConfig.__doc__ or ""
    block = "\n".join(line[8:] for line in doc.splitlines() if line.startswith("        "))
    data = tomllib.loads(block)
    cfg = parse_sort_config(data["sorting"])
    assert cfg.bin_for("red") is not None and cfg.obstacles[0].frame == "S"
    assert parse_registration_config(data["registration"]).offset[3] == 180.0


def test_example_cell_file_sorting_and_registration_sections_parse() -> None:
    """deploy/cell.example.toml documents [sorting] and [registration]; they must parse."""
    import tomllib
    from pathlib import Path

    example = Path(__file__).resolve().parents[2] / "deploy" / "cell.example.toml"
    data = tomllib.loads(example.read_text())
    cfg = parse_sort_config(data["sorting"])
    reg = parse_registration_config(data["registration"])
    assert cfg.robot_model == "UR5e" and cfg.bins and cfg.obstacles
    assert (reg.board.cols, reg.board.rows, reg.board.square_mm) == (9, 6, 40.0)


def test_registration_keys_are_checked_by_their_declaration() -> None:
    """`[registration]` is checked against `RegistrationSettings`, each problem naming its key
    with the bound or the choices it broke; `register-robot`'s flags are made from the same
    declaration, and its flags are checked by it too, named as flags."""
    import argparse

    from omnisort_hw.cli.request_flags import add_request_arguments
    from omnisort_hw.config.registration_settings import RegistrationSettings
    from omnisort_hw.config.sorting import REGISTRATION_KEYS, registration_config
    from omnisort_hw.errors import InputError

    good = {"board": "9x6", "square_mm": 40, "offset": [200, -180, 2, 180, 0, 90]}
    cases = {
        "square_mm": (0.5, "[registration].square_mm: must be a finite number within 1..1000 mm"),
        "offset": ([1, 2, 3], "[registration].offset: must be an array of 6 numbers"),
        "fit": ("tilted", "[registration].fit: must be one of auto, level, free"),
        "camera_height_mm": (-5, "[registration].camera_height_mm: must be a finite number"),
        "board": ("9by6", "[registration].board:"),
    }
    for key, (value, message) in cases.items():
        with pytest.raises(ConfigError) as err:
            parse_registration_config({**good, key: value})
        assert str(err.value).startswith(message), err.value
    reg = parse_registration_config({**good, "fit": "level", "camera_height_mm": 900})
    assert (reg.fit, reg.camera_height_mm, reg.offset[1]) == ("level", 900.0, -180.0)
    assert parse_registration_config(reg.settings()) == reg  # the record as keys, and back

    parser = argparse.ArgumentParser()
    add_request_arguments(parser, RegistrationSettings)
    flags = {a.dest: a.option_strings for a in parser._actions if a.dest in REGISTRATION_KEYS}
    assert flags == {
        "board": ["--board"],
        "square_mm": ["--square"],
        "offset": ["--offset"],
        "fit": ["--fit"],
        "camera_height_mm": ["--camera-height"],
    }
    args = parser.parse_args(["--square", "40", "--offset", "1,2,3,4,5"])
    values = {k: getattr(args, k) for k in REGISTRATION_KEYS if getattr(args, k) is not None}
    with pytest.raises(InputError, match="--offset: must be an array of 6 numbers"):
        registration_config(values, "register-robot", lambda a: a.cli_flag, InputError)
    with pytest.raises(SystemExit):
        parser.parse_args(["--offset", "1,2,x,4,5,6"])  # argparse: not numbers


def test_location_keys_are_checked_by_their_declaration(tmp_path: Path) -> None:
    """The `[sorting]` keys `locate` overrides are checked against `LocationSettings`, from
    the file as from the flags (which are made from it), each problem naming its key, or its
    flag, with the bound it broke."""
    import argparse

    from omnisort_hw.cli.request_flags import add_request_arguments
    from omnisort_hw.config.location_settings import (
        LOCATION_KEYS,
        LocationSettings,
        location_changes,
    )
    from omnisort_hw.errors import InputError

    cases = {
        "cube_size_mm": (0, "[sorting].cube_size_mm: must be a finite number within 1..1000 mm"),
        "region_S_mm": ([0, 1, 2], "[sorting].region_S_mm: must be an array of 4 numbers"),
    }
    for key, (value, message) in cases.items():
        with pytest.raises(ConfigError) as err:
            parse_sort_config({key: value})
        assert str(err.value).startswith(message), err.value
    with pytest.raises(ConfigError, match=r"\[sorting\]\.region_S_mm: expected xmin < xmax"):
        parse_sort_config({"region_S_mm": [500, -500, 0, 900]})
    with pytest.raises(ConfigError, match=r"\[sorting\]\.colors_file: .*missing\.toml"):
        parse_sort_config({"colors_file": "missing.toml"}, base_dir=tmp_path)
    cfg = parse_sort_config({"cube_size_mm": 80, "region_S_mm": [-500, 500, 100, 900]})
    assert (cfg.cube_size_mm, cfg.region_S_mm) == (80.0, (-500.0, 500.0, 100.0, 900.0))

    parser = argparse.ArgumentParser()
    add_request_arguments(parser, LocationSettings)
    flags = {a.dest: a.option_strings for a in parser._actions if a.dest in LOCATION_KEYS}
    assert flags == {
        "cube_size_mm": ["--cube-size"],
        "colors_file": ["--color-table"],
        "region_S_mm": ["--region"],
    }
    args = parser.parse_args(["--cube-size", "0", "--region=-500,500,100,900"])
    given = {k: getattr(args, k) for k in LOCATION_KEYS}
    with pytest.raises(InputError, match=r"--cube-size: must be a finite number within 1\.\.1000"):
        location_changes(given, lambda a: a.cli_flag, InputError)
    args = parser.parse_args(["--cube-size", "80", "--region=-500,500,100,900"])
    changes = location_changes({k: getattr(args, k) for k in LOCATION_KEYS}, lambda a: a.cli_flag)
    assert changes == {"cube_size_mm": 80.0, "region_S_mm": (-500.0, 500.0, 100.0, 900.0)}
