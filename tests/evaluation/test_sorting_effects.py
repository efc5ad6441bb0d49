"""The sorting experiment through a colour camera (`evaluate sorting --effects`): a scene seen
through the sensor and the colour camera's effects is registered, and each cube is either
sorted into its bin or refused as too uncertain to pick; none is dropped elsewhere, nothing
collides."""

from __future__ import annotations

import pytest

pytest.importorskip("pybullet", reason="the experiment runs on the simulated cell")

pytestmark = pytest.mark.slow


def test_a_scene_through_the_colour_camera_is_sorted() -> None:
    from omnisort_hw.evaluation.sorting import sort_scene, sorting_trials

    (trial,) = sorting_trials(1, seed=7, width=960, effects=True)
    assert trial.config["effects"] is True
    assert "effects" not in sorting_trials(1, seed=7, width=960)[0].config
    from omnisort_hw.runlog import NullLog

    row = sort_scene(trial.config, trial.seed, NullLog)
    assert "error" not in row, row.get("error")
    refused = [r for r in row["skipped"] if r.startswith("location too uncertain")]
    assert row["sorted_ok"] + len(refused) == row["cubes"] and row["collisions"] == 0, row
    assert row["sorted_ok"] > 0, row  # the effects do not blind the cell
    # Registered from the floor board through the effects: the goal of the clean cell.
    assert row["registration_error_mm"] < 2.0, row["registration_error_mm"]
