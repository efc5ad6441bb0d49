"""The simulator and the core agree on frames, signs and the laser plane (docs/frames.md).

Features made from the simulator's truth (not extracted from the image) must give back the
simulator's parameters through every two-sided method, to the lens model's round-trip
precision: a sign, order or offset mismatch anywhere shows up here as a systematic error.
"""

from __future__ import annotations

import numpy as np
import pytest

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.joint import calibrate_joint
from omnisort_hw.core.extrinsics.paper import calibrate_paper
from omnisort_hw.evaluation.table3 import features_from_truth, truth_parameters

pytest.importorskip("pybullet")


@pytest.fixture(scope="module")
def tilted_truth() -> dict:
    from sim_backend.scene import load_scene, sized
    from sim_backend.scene_images import render_scene

    scene = sized(load_scene("two_sided"), 480).replace(
        camera={"roll_deg": 6.0, "pitch_deg": -7.5, "yaw_deg": 4.0},
        laser={"roll_deg": 8.9, "pitch_deg": -9.2},
    )
    _, truth = render_scene(scene, seed=1)
    return truth


def test_truth_laser_polylines_lie_on_the_plane_through_the_emitter(tilted_truth: dict) -> None:
    n = np.asarray(tilted_truth["laser_plane"]["normal"])
    d = tilted_truth["laser_plane"]["distance_mm"]
    for line in tilted_truth["laser_polylines_S"]:
        pts = np.asarray(line["points_mm"])
        assert np.max(np.abs((pts - [0.0, 0.0, -d]) @ n)) < 1e-3, line["surface"]


@pytest.mark.parametrize("method", [calibrate_joint, calibrate_paper])
def test_methods_recover_the_simulator_parameters(tilted_truth: dict, method) -> None:
    features = features_from_truth(tilted_truth)
    model = OcamModel.from_dict(tilted_truth["camera"])
    calib = method(features, model, tilted_truth["target"]["separation_mm"])
    want = truth_parameters(tilted_truth)
    got = calib.parameters()
    for key in want:
        tol = 0.01 if key == "laser_distance_mm" else 1e-3
        assert got[key] == pytest.approx(want[key], abs=tol), key
