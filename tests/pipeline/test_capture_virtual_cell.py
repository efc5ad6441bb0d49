"""A measurement capture through the camera's stream source and the Modbus laser of the
virtual cell: the real OpenCV stream reader and the real pymodbus client, end to end."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from drivers.modbus_laser import ModbusLaser, ModbusLaserConfig
from drivers.v4l2_camera import V4L2Camera, V4L2CameraConfig
from omnisort_hw.core.laser_stripe import laser_stripe_points
from omnisort_hw.pipeline.measurement_capture import CaptureSettings, capture_measurement
from tests.sim.virtual_cell_fixture import virtual_cell

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]
WIDTH = 480


def test_capture_over_the_stream_and_modbus_finds_the_stripe_of_a_lit_frame() -> None:
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
            lit = cam.grab().image
            cap = capture_measurement(cam, laser, CaptureSettings(frames=2))
            assert laser.state() is True  # put back as it was
            laser.off()
    reference = laser_stripe_points(lit)
    assert len(reference) > 20
    assert "source cannot tell" in cap.record["pixel_format"]
    assert cap.record["response_gamma"] == 1.0  # a stream has no exposure control
    # the same stripe as in the lit frame: the reference is sampled on every scan line (one
    # pixel apart at this size), so a point on it is within a pixel and a half of one of them
    dist, _ = cKDTree(reference).query(cap.stripe_px)
    assert np.mean(dist < 1.5) > 0.9
    assert len(cap.stripe_px) > 0.5 * len(reference)
