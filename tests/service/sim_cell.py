"""The simulated sorting cell for fault tests: the demo's configuration, with the simulator's
true calibration written to the state directory (so no test spends minutes calibrating)."""

from __future__ import annotations

from pathlib import Path

from omnisort_hw.cell.cell import Cell
from omnisort_hw.config.cell import load_cell_config
from omnisort_hw.service.demo import calibrate_from_truth, write_config

WIDTH = 320


def calibrated_sim_cell(tmp: Path, width: int = WIDTH, devices_in_child: bool = False) -> Cell:
    """A connected simulated cell with the true calibration in its state directory;
    `devices_in_child`: the world in a child process, as the service opens it."""
    tmp.mkdir(parents=True, exist_ok=True)
    config = write_config(tmp, width)
    calibrate_from_truth(config)
    cell = Cell.from_settings(load_cell_config(config), devices_in_child=devices_in_child)
    cell.connect()
    return cell
