"""The uncertainty experiments on the simulated cell: the gated sort, and one map trial."""

from __future__ import annotations

import numpy as np

from omnisort_hw.core.cube_uncertainty import UNCERTAIN
from omnisort_hw.evaluation.uncertainty import gated_sort, map_trial


def test_a_cube_too_uncertain_for_the_gripper_is_refused_and_the_rest_sorted() -> None:
    out = gated_sort()
    by_colour = {c["color"]: c for c in out["cubes"]}
    assert by_colour["green"]["status"] == "skipped"
    assert by_colour["green"]["reason"].startswith(UNCERTAIN)
    assert by_colour["red"]["in_right_bin"] and by_colour["blue"]["in_right_bin"]
    assert out["sorted_ok"] == 2 and out["collisions"] == 0


def test_map_trial_gives_errors_and_sigmas_for_the_stripe_points() -> None:
    trial = map_trial(seed=0, width=960)
    assert len(trial.errors) > 50
    assert np.all(trial.sigmas > 0)
    walls = np.char.startswith(trial.surfaces, "wall")
    # Not the calibration of the sigmas (the benchmark measures it on held-out seeds):
    # that the errors are of the predicted order on the walls.
    z = trial.errors[walls] / trial.sigmas[walls]
    assert 0.2 < float(np.std(z)) < 5.0
