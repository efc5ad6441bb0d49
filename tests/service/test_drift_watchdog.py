"""The drift watchdog in the service on the simulated cell: a knock of the camera mount is
found by `check`, `sort` and `move` are refused with `calibration_drift` naming the angle,
`status` shows it, `acknowledge_drift` and a new registration lift the refusal."""

from __future__ import annotations

from pathlib import Path

import pytest

from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.service.client import Client
from omnisort_hw.service.server import Service, start_in_thread

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

WIDTH = 640
BUMP_DEG = 0.3


def test_bump_is_detected_refuses_motion_until_acknowledged_or_recalibrated(
    tmp_path: Path,
) -> None:
    from tests.service.sim_cell import calibrated_sim_cell

    cell = calibrated_sim_cell(tmp_path, width=WIDTH)
    sim = cell.devices.camera.cell  # type: ignore[union-attr]
    running = start_in_thread(Service(cell, ServiceConfig(port=0, job_timeout_s=240)))
    try:
        with Client(running.host, running.port, timeout_s=240) as c:
            # No reference image yet (calibrated from the truth file): the board alone says
            # the camera did not move, and this capture becomes the reference.
            assert c.call("laser", {"on": True})["result"]["on"] is True
            first = c.call("check")
            assert first["ok"], first
            # The check's dark frame leaves the laser as the operator set it.
            assert c.call("laser")["result"]["on"] is True
            assert first["result"]["drift"] is False
            assert first["result"]["source"] == "board"
            assert first["result"]["reference_adopted"] is True
            again = c.call("check")["result"]
            assert again["source"] == "image" and again["drift"] is False
            assert again["angle_deg"] < 0.01

            sim.bump_camera(BUMP_DEG, "y")
            found = c.call("check")["result"]
            assert found["drift"] is True
            assert abs(found["angle_deg"] - BUMP_DEG) < 0.02
            assert found["rotvec_deg"][1] == pytest.approx(BUMP_DEG, abs=0.02)

            st = c.call("status")["result"]
            assert st["drift"]["motion_refused"] is True
            assert st["drift"]["last"]["drift"] is True
            sort = c.call("sort")
            assert not sort["ok"]
            assert sort["error"]["code"] == "calibration_drift"
            assert f"{found['angle_deg']:.3f} deg" in sort["error"]["message"]
            move = c.call("move", {"joints_deg": [180, -60, -120, -90, 90, 0]})
            assert move["error"]["code"] == "calibration_drift"
            assert c.call("status")["result"]["state"] != "fault"

            ack = c.call("acknowledge_drift")
            assert ack["ok"] and ack["result"]["acknowledged"] is True
            assert c.call("status")["result"]["drift"]["motion_refused"] is False
            # The next check still sees the turned camera and refuses again; `ctl check`
            # says so by its exit code, as `omnisort check` does.
            assert _ctl_check(running.port) == 4
            assert c.call("status")["result"]["drift"]["motion_refused"] is True

            # A new registration (with the camera as it is now) is a new calibration.
            reg = c.call("register_robot")
            assert reg["ok"], reg
            assert c.call("status")["result"]["drift"]["motion_refused"] is False
            after = c.call("check")["result"]
            assert after["source"] == "image" and after["drift"] is False
            assert _ctl_check(running.port) == 0
    finally:
        running.stop()


def _ctl_check(port: int) -> int:
    """`omnisort ctl check`'s exit code."""
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "omnisort_hw.cli", "ctl", "--port", str(port), "check"]
    return subprocess.run(cmd, capture_output=True, timeout=240).returncode
