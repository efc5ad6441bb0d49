"""The simulated camera mount can be knocked: `bump_camera` and the camera's `bump_*` keys
turn R_SC by the given angle about the given axis of S, once, between grabs."""

from __future__ import annotations

import numpy as np
import pytest

from omnisort_hw.core.frames import rotation_angle_deg

pytest.importorskip("pybullet")
pytestmark = pytest.mark.timeout(120)


def test_bump_after_grabs_turns_the_camera_once() -> None:
    from sim_backend.devices import open_devices

    devs = open_devices(
        {
            "camera": {
                "width": 160,
                "height": 160,
                "bump_deg": 0.3,
                "bump_axis": "z",
                "bump_after_grabs": 1,
            }
        }
    )
    cam = devs["camera"]
    cam.connect()
    try:
        cam.grab(with_truth=True)
        R0 = np.asarray(cam.last_truth["camera_rotation"]["matrix"], float)
        cam.grab(with_truth=True)
        R1 = np.asarray(cam.last_truth["camera_rotation"]["matrix"], float)
        cam.grab(with_truth=True)
        R2 = np.asarray(cam.last_truth["camera_rotation"]["matrix"], float)
    finally:
        cam.close()
        cam.cell.close()
    assert float(rotation_angle_deg(R0, R1)) == pytest.approx(0.3, abs=1e-6)
    axis = R1 @ R0.T
    assert axis[0, 1] == pytest.approx(-np.sin(np.radians(0.3)), abs=1e-9)  # about +Z of S
    assert float(rotation_angle_deg(R1, R2)) < 1e-9


def test_bad_axis_is_refused() -> None:
    from sim_backend.devices import SimCell

    cell = SimCell.from_scene("sorting", width=160, height=160)
    try:
        with pytest.raises(ValueError, match="axis"):
            cell.bump_camera(0.1, [0.0, 0.0, 0.0])
    finally:
        cell.close()
