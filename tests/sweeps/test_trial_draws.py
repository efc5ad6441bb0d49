"""The sorting experiment's trials make main's seeded draws: the scenes (cube colours,
positions, yaws, camera angles) and the calibration errors of `--calibration perturbed` are
those `evaluate_sorting` drew scene after scene before it became a set of trials
(data/sorting_draws_main.json, recorded from that code), so its figures stay the same. The
whole rows were compared too (2 scenes each, truth and perturbed, 960 px: identical but for
timing); that check renders and sorts, too slow for the suite."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.evaluation.sorting import perturbed, sorting_trials
from sim_backend.scene_images import camera_model_for

GOLDEN = json.loads((Path(__file__).parent / "data" / "sorting_draws_main.json").read_text())


@pytest.mark.parametrize("calibration", ["truth", "perturbed"])
def test_the_trials_draw_what_the_experiment_drew(calibration: str) -> None:
    want = GOLDEN[calibration]
    trials = sorting_trials(len(want), GOLDEN["seed"], GOLDEN["width"], calibration)
    assert [t.seed for t in trials] == [GOLDEN["seed"] * 1000 + k for k in range(len(want))]
    fixed = {
        "cam_roll_deg": 1.0,
        "cam_pitch_deg": -2.0,
        "cam_yaw_deg": 3.0,
        "laser_roll_deg": 0.5,
        "laser_pitch_deg": -0.5,
        "laser_distance_mm": 800.0,
    }
    from sim_backend.scene import load_scene, sized

    model = camera_model_for(sized(load_scene("sorting"), GOLDEN["width"]))
    calib = SystemCalibration.from_angles(model, fixed, "fixed")
    for trial, scene in zip(trials, want, strict=True):
        layout = trial.config["layout"]
        cam = layout["camera"]
        assert [cam["roll_deg"], cam["pitch_deg"], cam["yaw_deg"]] == scene["camera"]
        assert layout["cubes"] == scene["cubes"]
        assert layout["bins"][: len(scene["bins"])] == scene["bins"]
        if calibration == "perturbed":
            got = perturbed(calib, trial.config["calibration_errors"]).parameters()
            # the draws are exact; the parameters pass through trigonometry, which may
            # differ in the last bit between machines and libm builds
            assert got == pytest.approx(scene["perturbed"], rel=1e-12, abs=1e-12)
        else:
            assert "calibration_errors" not in trial.config
