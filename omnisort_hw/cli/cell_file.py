"""The cell file as the commands read it: its typed record and its devices (unconnected). Its
`[sorting]`, resolved as the service resolves it at start, is the file rig's `sort_config`."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # imported by the function: a command's --help stays quick
    from omnisort_hw.cell.devices import Devices
    from omnisort_hw.config.cell import CellConfig


def load_cell(config: Path, devices: bool = True) -> tuple[CellConfig, Devices | None]:
    """The cell file's typed record and (unless `devices` is False) its devices, unconnected."""
    from omnisort_hw.cell.devices import open_devices
    from omnisort_hw.config.cell import load_cell_config

    cell = load_cell_config(config)
    return cell, open_devices(cell.devices) if devices else None
