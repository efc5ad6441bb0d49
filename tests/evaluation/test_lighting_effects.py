"""The hostile-light sweep through a colour camera (`evaluate lighting --effects`): the cell's
frames go through the colour camera's effects, and both acquisitions still map the stripe."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pybullet", reason="the scenarios run on the simulated cell")

WIDTH = 256  # small: what is checked is that the effects are applied, not their figures


def _frame(effects: bool) -> np.ndarray:
    from omnisort_hw.evaluation.lighting import lighting_cell

    cell = lighting_cell("red_objects", 3, WIDTH, effects)
    try:
        image, _ = cell.render(5, degraded=True, laser_on=True)
    finally:
        cell.close()
    return image


def test_the_colour_cameras_effects_change_the_scenarios_frames() -> None:
    plain, coloured = _frame(False), _frame(True)
    assert plain.shape == coloured.shape == (WIDTH, WIDTH, 3)
    # The same render and sensor noise, through the effects or not: a Bayer mosaic alone
    # changes most pixels of a textured scene by more than the sensor's noise.
    changed = np.abs(plain.astype(int) - coloured.astype(int)).max(axis=2) > 8
    assert changed.mean() > 0.05, changed.mean()


def test_a_scenario_through_the_colour_camera_is_measured_like_the_plain_one() -> None:
    """Red objects in the cell, 640 px, 2 frame pairs (below that the capture's difference is
    under its noise floor with or without the effects): through the colour camera the
    capture still finds the stripe, and its laser on/off difference still leaves no phantom."""
    from omnisort_hw.evaluation.lighting import lighting_trials, run_scenario

    assert lighting_trials(3, 2, 640, ("red_objects",), effects=True)[0].config["effects"]
    assert "effects" not in lighting_trials(3, 2, 640, ("red_objects",))[0].config
    plain = run_scenario("red_objects", 3, frames=2, width=640, calibrate=False)
    coloured = run_scenario("red_objects", 3, frames=2, width=640, calibrate=False, effects=True)
    assert coloured["effects"] is True and "effects" not in plain
    for result in (plain, coloured):
        assert "error" not in result["capture"], result["capture"]
        assert result["capture"]["spurious_points"] == 0, result["capture"]
    found = coloured["capture"]["laser_points"], plain["capture"]["laser_points"]
    assert found[0] >= 0.5 * found[1] > 0, found  # the stripe, not lost to the effects
