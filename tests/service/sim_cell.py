"""The simulated sorting cell for fault tests: the demo's configuration, with the simulator's
true calibration written to the state directory (so no test spends minutes calibrating)."""

from __future__ import annotations

from pathlib import Path

from omnisort_hw.cell.cell import Cell
from omnisort_hw.config.cell import load_cell_config
from omnisort_hw.service.demo import calibrate_from_truth, write_config

WIDTH = 320
# The sort's moves near the arm's caps (drivers.ur_arm: 179.9 deg/s, 300 deg/s^2) and at
# a brisk linear pace, as a commissioned cell runs: a paced pick takes about 4 s instead of
# the scene's cautious 9 s, still long enough to watch and stop.
FAST_MOVES = (
    "joint_speed_deg_s = 170.0\njoint_accel_deg_s2 = 300.0\n"
    "linear_speed_mm_s = 500.0\nlinear_accel_mm_s2 = 2000.0\n"
)


def pace_the_arm(config: Path) -> None:
    """Make the simulated arm of the cell file `config` move at the wall clock's pace (as a
    real arm does), so a sort lasts long enough to be watched and stopped: a pick takes about
    5 s at `FAST_MOVES` instead of a fraction of one."""
    text = config.read_text()
    arm = '[arm]\nbackend = "sim"\nscene = "sorting"\n'
    assert arm in text, "the simulated cell file changed its [arm] section"
    config.write_text(text.replace(arm, arm + "realtime = true\n"))
    brisk_sort(config)


def brisk_sort(config: Path) -> None:
    """The sort of the cell file `config` at `FAST_MOVES`: for an arm that moves at the wall
    clock's pace (the paced simulated arm, the virtual cell's emulated controller)."""
    text = config.read_text()
    sorting = "[sorting]\n"
    assert text.count(sorting) == 1, f"{config}: no single [sorting] section"
    config.write_text(text.replace(sorting, sorting + FAST_MOVES))


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
