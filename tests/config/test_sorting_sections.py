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
