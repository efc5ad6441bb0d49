"""`[watchdog]`, `[plc]` and the live-view keys of `[logging]`: defaults, values, and a typed
error naming the key for anything wrong; docs/plc.md lists the registers the code serves."""

from __future__ import annotations

from pathlib import Path

import pytest

from omnisort_hw.config.cell import CellConfig
from omnisort_hw.errors import ConfigError


def test_defaults_are_safe() -> None:
    cfg = CellConfig.from_mapping({})
    assert cfg.watchdog.before_sort and cfg.watchdog.period_s == 600.0
    assert cfg.plc.modbus_port is None and not cfg.plc.allow_commands and cfg.plc.on_loopback
    assert not cfg.logging.live.enabled and cfg.logging.live.host == "127.0.0.1"


def test_values_are_read() -> None:
    cfg = CellConfig.from_mapping(
        {
            "watchdog": {"period_s": 30, "before_sort": False, "min_angle_deg": 0.05},
            "plc": {"modbus_port": 1502, "host": "10.0.0.5", "allow_commands": True},
            "logging": {"live": True, "live_port": 9877, "live_memory_limit": "1GiB"},
        }
    )
    assert cfg.watchdog.period_s == 30.0 and not cfg.watchdog.before_sort
    assert cfg.plc.modbus_port == 1502 and cfg.plc.allow_commands and not cfg.plc.on_loopback
    assert cfg.logging.live.port == 9877 and cfg.logging.live.memory_limit == "1GiB"


@pytest.mark.parametrize(
    ("doc", "names"),
    [
        ({"watchdog": {"period": 3}}, "period"),
        ({"watchdog": {"period_s": -1}}, "period_s"),
        ({"watchdog": {"before_sort": "yes"}}, "before_sort"),
        ({"plc": {"modbus_port": 70000}}, "modbus_port"),
        ({"plc": {"modbus_port": True}}, "modbus_port"),
        ({"plc": {"allow_commands": 1}}, "allow_commands"),
        ({"plc": {"coils": 3}}, "coils"),
        ({"logging": {"live": "on"}}, "live"),
        ({"logging": {"live_port": -2}}, "live_port"),
        ({"logging": {"live_memory_limit": "lots"}}, "live_memory_limit"),
    ],
)
def test_wrong_values_name_the_key(doc: dict, names: str) -> None:
    with pytest.raises(ConfigError, match=names):
        CellConfig.from_mapping(doc)


def test_plc_doc_lists_every_register() -> None:
    from omnisort_hw.service.plc_face import REGISTERS

    text = (Path(__file__).parents[2] / "docs" / "plc.md").read_text()
    for address, (name, meaning) in enumerate(REGISTERS):
        assert f"| {address} | `{name}` | {meaning} |" in text
