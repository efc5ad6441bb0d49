"""A measurement capture through the camera's stream source and the Modbus laser of the
virtual cell: the real OpenCV stream reader and the real pymodbus client, end to end."""

from __future__ import annotations

import pytest

from drivers.modbus_laser import ModbusLaser, ModbusLaserConfig
from drivers.v4l2_camera import V4L2Camera, V4L2CameraConfig
from omnisort_hw.config.capture import CaptureSettings
from omnisort_hw.evaluation.lighting import score_points
from omnisort_hw.pipeline.measurement_capture import capture_measurement
from sim_backend.devices import SimCamera, SimCell, SimLaserSwitch
from tests.sim.virtual_cell_fixture import virtual_cell

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]
WIDTH = 480


def test_capture_over_the_stream_and_modbus_maps_only_the_true_stripe() -> None:
    with virtual_cell(width=WIDTH) as vc:
        cam = V4L2Camera(
            V4L2CameraConfig(
                device=f"http://{vc.host}:8080/stream.mjpg?quality=100&sampling=444",
                api="stream",
                fps=10.0,
                read_timeout_s=30.0,
                tone_curve="linear",
            )
        )
        laser = ModbusLaser(ModbusLaserConfig(host=vc.host, tcp_port=5020, timeout_s=1.0))
        with cam, laser:
            laser.on()
            cap = capture_measurement(cam, laser, CaptureSettings(frames=2))
            assert laser.state() is True  # put back as it was
            laser.off()
    assert "source cannot tell" in cap.record["pixel_format"]
    assert cap.record["response_gamma"] == 1.0  # a stream has no exposure control
    # Truth from the same scene in this process (the virtual cell renders the same world):
    # every capture point lies on a true laser line, or on a pixel the laser lights directly.
    cell = SimCell.from_scene("sorting", width=WIDTH, height=WIDTH)
    try:
        with SimCamera(cell, degraded=True) as sim_cam, SimLaserSwitch(cell) as sim_laser:
            sim_laser.on()
            sim_cam.grab(with_truth=True)
            truth, direct = sim_cam.last_truth, sim_cam.direct_laser
    finally:
        cell.close()
    assert truth is not None
    score = score_points(cap.stripe_px, truth, direct)
    assert score["laser_points"] > 20
    assert score["spurious_points"] == 0
