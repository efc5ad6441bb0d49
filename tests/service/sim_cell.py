"""The simulated sorting cell for fault tests: the demo's configuration, with the simulator's
true calibration written to the state directory (so no test spends minutes calibrating)."""

from __future__ import annotations

from pathlib import Path

from omnisort_hw.cell.cell import Cell
from omnisort_hw.config.cell import load_cell_config
from omnisort_hw.service.demo import calibrate_from_truth, write_config

WIDTH = 320


def pace_the_arm(config: Path) -> None:
    """Make the simulated arm of the cell file `config` move at the wall clock's pace (as a
    real arm does), so a sort lasts long enough to be watched and stopped: a pick takes about
    9 s instead of a fraction of one."""
    text = config.read_text()
    arm = '[arm]\nbackend = "sim"\nscene = "sorting"\n'
    assert arm in text, "the simulated cell file changed its [arm] section"
    config.write_text(text.replace(arm, arm + "realtime = true\n"))


def calibrated_sim_cell(
    tmp: Path, width: int = WIDTH, devices_in_child: bool = False, realtime: bool = False
) -> Cell:
    """A connected simulated cell with the true calibration in its state directory;
    `devices_in_child`: the world in a child process, as the service opens it; `realtime`: the
    arm paced to the wall clock (`pace_the_arm`)."""
    tmp.mkdir(parents=True, exist_ok=True)
    config = write_config(tmp, width)
    calibrate_from_truth(config)
    if realtime:
        pace_the_arm(config)
    cell = Cell.from_settings(load_cell_config(config), devices_in_child=devices_in_child)
    cell.connect()
    return cell
