"""The cell's sort measures with a measurement capture: the board image (laser off, averaged)
for colours, the laser-light image for heights, and the capture's record in the report."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")

from omnisort_hw.pipeline.calibration_source import StoreCalibration
from omnisort_hw.pipeline.sort import Sorter
from omnisort_hw.pipeline.sort_capture import sort_capture_for
from tests.service.sim_cell import calibrated_sim_cell


def test_the_cells_sort_locates_from_a_capture_and_records_it(tmp_path: Path) -> None:
    cell = calibrated_sim_cell(tmp_path)
    try:
        acquire = sort_capture_for(cell.jobs, cell.jobs.laser_off)
        assert acquire is not None
        devs = cell.devices
        sorter = Sorter(
            devs.camera,
            devs.arm,
            devs.laser,
            StoreCalibration(cell.store),
            cell.sort_config,
            cell.registration_config,
            acquire=acquire,
        )
        single = Sorter(
            devs.camera,
            devs.arm,
            devs.laser,
            StoreCalibration(cell.store),
            cell.sort_config,
            cell.registration_config,
        )
        loc = sorter.locate()
        rec = loc.diagnostics["capture"]["capture"]
        assert rec["method"] == "laser on/off difference"
        assert rec["frames"] == cell.config.capture.frames
        assert rec["frames_grabbed"] >= 4 * rec["frames"]  # board x2 exposures, on/off pairs
        assert Path(loc.diagnostics["capture"]["path"]).is_file()
        assert devs.laser.state() is False  # the capture put the laser back off
        # the same cubes as from single frames, at the same places (within a cube's tenth)
        ref = single.locate()
        assert len(loc.cubes) == len(ref.cubes) > 0
        got = np.array(sorted(list(c.center_S[:2]) for c in loc.cubes))
        want = np.array(sorted(list(c.center_S[:2]) for c in ref.cubes))
        size = cell.sort_config.cube_size_mm
        assert np.abs(got - want).max() < 0.1 * size
        # without differencing the sort keeps its single frames
        from dataclasses import replace

        cell.config = replace(cell.config, capture=replace(cell.config.capture, differencing=False))
        assert sort_capture_for(cell.jobs, cell.jobs.laser_off) is None
    finally:
        cell.close()
