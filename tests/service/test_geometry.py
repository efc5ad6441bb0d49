"""`geometry`, the cell in 3D for a screen, on the simulated cell served in a thread with its
true calibration: the camera's rotation as stored, a laser patch on the stored plane, the arm's
links where the simulator's arm stands (its joints as the service last read them, through the
core's forward kinematics and the registered base), the bins of `[sorting]` where the
simulator put them; open to a client without a token, and each part missing with why."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.service.client import Client
from omnisort_hw.service.server import Service, start_in_thread

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

TOKEN = "geometry-test-token-7781"


def test_the_cell_in_3d_is_where_the_simulator_has_it(tmp_path: Path) -> None:
    from tests.service.sim_cell import calibrated_sim_cell

    cell = calibrated_sim_cell(tmp_path, width=320)
    world = cell.devices.arm.cell.world  # type: ignore[union-attr]
    system = json.loads((tmp_path / "state" / "system.json").read_text())
    running = start_in_thread(Service(cell, ServiceConfig(port=0, token=TOKEN)))
    try:
        with Client(running.host, running.port, timeout_s=60) as anyone:
            geometry = anyone.geometry()  # read as its record
        joints = world.joints()
        T_S_B = np.asarray(world.T_S_B, float)
        ur = world.ur
        (tmp_path / "state" / "system.json").unlink()
        with Client(running.host, running.port, timeout_s=60) as anyone:
            missing = anyone.geometry()
    finally:
        running.stop()

    from omnisort_hw.core.kinematics import joint_frames

    R = np.asarray(system["camera_rotation"]["matrix"], float)
    assert np.allclose(geometry.camera_R_SC, R, atol=1e-8)
    plane = geometry.laser_plane
    assert plane is not None
    n, d = np.asarray(plane.normal), plane.distance_mm
    corners = np.asarray(plane.corners_S_mm)
    # On the plane through the emitter (0, 0, -d), to the 0.01 mm the reply rounds to.
    assert np.abs(corners @ n + d * n[2]).max() < 0.02
    assert np.allclose(corners.mean(axis=0), [0.0, 0.0, -d], atol=0.02)

    # The arm where the simulator's arm stands: each joint origin within a hundredth of a
    # millimetre (the reply's rounding), through the base the registration stored (the truth
    # here) and the joints the service read.
    truth_B = np.vstack([np.zeros(3), joint_frames(ur, joints)[:, :3, 3]])
    truth_S = truth_B @ T_S_B[:3, :3].T + T_S_B[:3, 3]
    arm = geometry.arm
    assert arm is not None
    assert np.allclose(arm.joints_deg, joints, atol=1e-3)
    assert np.abs(np.asarray(arm.points_S_mm) - truth_S).max() < 0.05
    assert geometry.floor_z_mm == pytest.approx(T_S_B[2, 3], abs=0.01)

    # The bins of [sorting] (from the scene) over the simulator's bins.
    scene_bins = {b.color.name: b for b in world.scene.bins}
    assert {b.color for b in geometry.bins} == set(scene_bins)
    for b in geometry.bins:
        centre = np.asarray(b.floor_S_mm).mean(axis=0)
        assert np.allclose(centre[:2], scene_bins[b.color].position_mm, atol=0.05), b
    assert geometry.problems == []

    assert missing.camera_R_SC is None and missing.arm is None
    assert "system.json" in missing.problems[0], missing.problems
