"""The cell file as the commands read it: its typed record, its devices (unconnected), and its
`[sorting]` resolved as the service resolves it at start."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def load_cell(config: Path, devices: bool = True) -> tuple[Any, Any]:
    """The cell file's typed record and (unless `devices` is False) its devices, unconnected."""
    from omnisort_hw.cell.devices import open_devices
    from omnisort_hw.config.cell import load_cell_config

    cell = load_cell_config(config)
    return cell, open_devices(cell.devices) if devices else None


def sorting_config(config: Path) -> Any:
    """The `[sorting]` record of the cell file, resolved (`from_scene`: the scene of the cell's
    backend fills in what the section leaves out), or None without a `[sorting]` section."""
    from omnisort_hw.cell.devices import open_devices
    from omnisort_hw.pipeline.sort import resolve_sorting

    cell, _ = load_cell(config, devices=False)
    if cell.sorting is None:
        return None
    scene = open_devices(cell.devices).scene if cell.sorting.from_scene else None
    return resolve_sorting(cell.sorting, cell.registration, scene)[0]
