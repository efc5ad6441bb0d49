"""`[ui]` of the cell file: defaults bind to loopback, and a wrong value names its key."""

from __future__ import annotations

from pathlib import Path

import pytest

from omnisort_hw.config.ui import UiConfig, load_ui_settings
from omnisort_hw.errors import ConfigError


def test_defaults_are_loopback_with_operators_allowed() -> None:
    ui = UiConfig.from_mapping({})
    assert (ui.host, ui.allow_operator, ui.view_width_px) == ("127.0.0.1", True, 960)
    assert ui.sim_control is None  # no Simulator tab unless the cell is a virtual cell
    assert UiConfig.from_mapping({"sim_control": "127.0.0.2:30111"}).sim_control == (
        "127.0.0.2",
        30111,
    )


@pytest.mark.parametrize(
    ("section", "key"),
    [
        ({"port": 70000}, "port"),
        ({"host": ""}, "host"),
        ({"allow_operator": "no"}, "allow_operator"),
        ({"status_period_s": 0.0}, "status_period_s"),
        ({"view_width_px": 10}, "view_width_px"),
        ({"colour": "red"}, "colour"),
        ({"sim_control": "127.0.0.2"}, "sim_control"),
        ({"sim_control": "127.0.0.2:http"}, "sim_control"),
        ({"sim_control": 30111}, "sim_control"),
    ],
)
def test_a_wrong_value_names_its_key(section: dict, key: str) -> None:
    with pytest.raises(ConfigError, match=key):
        UiConfig.from_mapping(section)


def test_the_file_and_the_service_address(tmp_path: Path) -> None:
    cell = tmp_path / "cell.toml"
    cell.write_text('[service]\nhost = "0.0.0.0"\nport = 29111\n[ui]\nview_period_s = 1.0\n')
    settings = load_ui_settings(cell)
    assert (settings.service_host, settings.service_port) == ("127.0.0.1", 29111)
    cell.write_text("[ui]\nport = -1\n")
    with pytest.raises(ConfigError, match=rf"{cell}.*\[ui\] port"):
        load_ui_settings(cell)
