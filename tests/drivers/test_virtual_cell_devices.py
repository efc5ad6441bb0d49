"""The real camera (OpenCV reading the MJPEG stream) and the real Modbus laser driver (pymodbus
client) against the virtual cell: their contracts, the laser seen in the next frame, typed
errors for a bad coil address and for stalled peers."""

from __future__ import annotations

import time

import numpy as np
import pytest

from drivers.errors import BadReplyError, DeviceNotFoundError, DeviceTimeoutError
from drivers.modbus_laser import ModbusLaser, ModbusLaserConfig
from drivers.v4l2_camera import V4L2Camera, V4L2CameraConfig
from sim_backend.virtual_cell.launcher import VirtualCellError
from tests.drivers.contract import CameraContract, LaserSwitchContract
from tests.sim.virtual_cell_fixture import virtual_cell

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]
WIDTH = 192


@pytest.fixture(scope="module")
def vc():
    with virtual_cell(width=WIDTH) as cell:
        yield cell


def camera(host: str, **overrides: object) -> V4L2Camera:
    settings = {
        "device": f"http://{host}:8080/stream.mjpg?quality=95",
        "api": "stream",
        "fps": 10.0,
        "read_timeout_s": 20.0,
        "open_timeout_s": 5.0,
        "reconnect_attempts": 2,
        "reconnect_backoff_s": 0.1,
        **overrides,
    }
    return V4L2Camera(V4L2CameraConfig(**settings))  # type: ignore[arg-type]


def laser(host: str, **overrides: object) -> ModbusLaser:
    settings = {"host": host, "tcp_port": 5020, "timeout_s": 0.5, "retries": 0, **overrides}
    return ModbusLaser(ModbusLaserConfig(**settings))  # type: ignore[arg-type]


class TestStreamCameraOnVirtualCell(CameraContract):
    @pytest.fixture
    def make_camera(self, vc):
        return lambda: camera(vc.host)


class TestModbusLaserOnVirtualCell(LaserSwitchContract):
    @pytest.fixture
    def make_laser(self, vc):
        return lambda: laser(vc.host)


def _changed(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pixels that differ by more than 10 levels in some channel."""
    return np.abs(a.astype(int) - b).max(axis=2) > 10


def test_the_laser_switched_over_modbus_is_in_the_next_frame(vc) -> None:
    with laser(vc.host) as sw, camera(vc.host) as cam:
        sw.off()
        dark = cam.grab().image
        sw.on()
        lit = cam.grab().image
        sw.off()
        dark_again = cam.grab().image
        assert vc.truth()["laser_on"] is False
    # The faint stripe (1 px at this size) changes about 30 pixels. A stale lit frame would
    # repeat all of them; cubes still settling may move a few pixels anywhere, stripe included,
    # so at most a fifth of the stripe may differ from the first dark frame.
    stripe = _changed(dark, lit)
    assert np.count_nonzero(stripe) >= 15
    assert np.count_nonzero(stripe & _changed(dark, dark_again)) <= np.count_nonzero(stripe) // 5


def test_a_coil_outside_the_module_is_an_exception_reply(vc) -> None:
    with pytest.raises(BadReplyError, match="ILLEGAL DATA ADDRESS"):
        laser(vc.host, coil=40).connect()


def test_stalled_laser_module_gives_device_timeout(vc) -> None:
    with laser(vc.host) as sw:
        vc.control("stall", what="laser", seconds=2.0)
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeoutError):
            sw.on()
        assert time.monotonic() - t0 < 2.0
        time.sleep(2.0)


def test_stalled_camera_gives_device_timeout_then_recovers(vc) -> None:
    with camera(vc.host, read_timeout_s=1.0) as cam:
        cam.grab(timeout_s=20.0)
        vc.control("stall", what="camera", seconds=2.5)
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeoutError):
            cam.grab()
        assert time.monotonic() - t0 < 2.0
        time.sleep(2.5)
        assert cam.grab(timeout_s=20.0).image.shape[:2] == (WIDTH, WIDTH)


def test_a_stream_nobody_serves_is_device_not_found(vc) -> None:
    host = vc.host.rsplit(".", 1)[0] + ".1"
    with pytest.raises(DeviceNotFoundError):
        camera(host, device=f"http://{host}:8081/stream.mjpg").connect()


def test_a_held_board_is_in_the_next_frame_and_put_down_again(vc) -> None:
    from sim_backend.scene import load_scene, sized
    from sim_backend.scene_images import render_scene
    from sim_backend.virtual_cell.held_board import HELD_VIEWS, held_board_scene

    cell_scene = sized(load_scene("sorting"), WIDTH)
    with camera(vc.host) as cam:
        before = cam.grab().image
        shown = vc.control("board", timeout_s=60.0, view=HELD_VIEWS - 1)
        held = cam.grab().image
        second = vc.control("board", timeout_s=60.0, view=0)
        other = cam.grab().image
        vc.control("board", timeout_s=60.0, view=None)
        after = cam.grab().image
        with pytest.raises(
            VirtualCellError, match=r"'view' must be a finite number within 0\.\.11"
        ):
            vc.control("board", view=HELD_VIEWS)
    assert shown == {"view": HELD_VIEWS - 1, "views": HELD_VIEWS, "shown": True}
    assert second["shown"]
    # The frame is the calibration screen's render of that pose through the cell's lens
    # (within the stream's JPEG noise: 0.8 levels here, against 12 for another pose), and the
    # cell is back once the board is put down.
    for view, frame in ((HELD_VIEWS - 1, held), (0, other)):
        expected, _ = render_scene(held_board_scene(cell_scene, view), seed=view)
        assert np.abs(frame.astype(float) - expected).mean() < 2.0, view
    assert np.count_nonzero(_changed(before, held)) > 0.2 * WIDTH * WIDTH
    assert np.count_nonzero(_changed(before, after)) < 0.01 * WIDTH * WIDTH


def test_the_camera_mounted_or_knocked_is_rendered_so(vc) -> None:
    from omnisort_hw.core.frames import rotation_angle_deg
    from sim_backend.scene import load_scene, sized
    from sim_backend.scene_images import render_scene

    scene = sized(load_scene("sorting"), WIDTH)
    with camera(vc.host) as cam:
        mounted = vc.control("camera", timeout_s=60.0, roll_deg=5.0)
        rolled = cam.grab().image
        truth = vc.truth()
        knocked = vc.control("knock", timeout_s=60.0, angle_deg=0.5, axis="y")
        after_knock = vc.truth()
        vc.control("camera", timeout_s=60.0)  # back to the scene's mounting
        level = cam.grab().image
    assert mounted["shown"] and knocked["shown"]
    # The truth reports the mounting asked, and the knock's turn from it.
    assert abs(truth["camera_rotation"]["roll_deg"] - 5.0) < 1e-6, truth["camera_rotation"]
    R5 = np.asarray(truth["camera_rotation"]["matrix"], float)
    Rk = np.asarray(after_knock["camera_rotation"]["matrix"], float)
    assert abs(float(rotation_angle_deg(R5, Rk)) - 0.5) < 1e-6
    # The streamed frame is the scene rendered at 5 deg of roll, not at 0 (within the stream's
    # JPEG noise and the cubes' settling, against what 5 deg changes).
    at_5, _ = render_scene(scene.replace(camera={"roll_deg": 5.0}), seed=0)
    at_0, _ = render_scene(scene, seed=0)
    near = np.abs(rolled.astype(float) - at_5).mean()
    far = np.abs(rolled.astype(float) - at_0).mean()
    assert near < far / 4, (near, far)
    assert np.abs(level.astype(float) - at_0).mean() < far / 4
