"""The camera's transfer curve reaches the extrinsic calibration: the cell calibrates with the
curve its camera reports, so the simulated cell (whose shipped scenes render linear) is not
calibrated as if it were an sRGB camera."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from omnisort_hw.core.radiometry import SRGB
from omnisort_hw.evaluation.table3 import truth_parameters
from omnisort_hw.pipeline.extrinsics import calibrate_system
from omnisort_hw.pipeline.requests import CalibrateRequest
from tests.service.sim_cell import calibrated_sim_cell


def test_the_simulated_cell_calibrates_with_its_cameras_own_curve(tmp_path: Path) -> None:
    cell = calibrated_sim_cell(tmp_path / "cell", width=960)
    try:
        camera = cell.devices.camera
        assert camera is not None
        cell.set_laser(True)
        frame = camera.grab(with_truth=True)
        truth = camera.last_truth  # type: ignore[attr-defined]
        cell.set_laser(False)
        # The simulated camera reports what its frames are written with (the shipped scenes
        # render linear), and the cell takes the curve from its camera.
        assert camera.tone_curve == truth["render"]["tone_curve"] == "linear"
        assert cell.jobs.tone_curve().name == "linear"
        image = tmp_path / "target.png"
        assert cv2.imwrite(str(image), frame.image)
        want = truth_parameters(truth)

        result = cell.jobs.calibrate_extrinsics(
            CalibrateRequest(
                "extrinsics",
                image=str(image),
                target="two-sided",
                separation_mm=truth["target"]["separation_mm"],
            )
        )
        assert result.tone_curve == "linear"
        roll_err = result.parameters["cam_roll_deg"] - want["cam_roll_deg"]
        roll_std = result.std["cam_roll_deg"]
        assert abs(roll_err) < 3 * roll_std, (roll_err, roll_std)

        # The same image calibrated as if the camera wrote sRGB: the borders' edges lean and
        # camera roll moves far beyond the calibration's own noise (the mismatch this fixes).
        wrong = calibrate_system(
            np.asarray(frame.image),
            cell.store.camera_model(),
            "two-sided",
            None,
            separation_mm=truth["target"]["separation_mm"],
            tone=SRGB,
        )
        wrong_err = wrong.parameters()["cam_roll_deg"] - want["cam_roll_deg"]
        assert abs(wrong_err) > 5 * roll_std, (wrong_err, roll_std)
    finally:
        cell.close()
