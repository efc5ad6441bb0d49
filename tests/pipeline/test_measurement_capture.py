"""Measurement captures through the real driver paths available here: the OpenCV file source
(frames rendered by the simulated camera, laser on and off), the Modbus laser (a pymodbus
server on loopback) and the serial laser (an emulator on a pty); and on the simulated cell
itself for re-exposure. Outcomes are physical: stripe points against the renderer's truth."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from drivers.errors import DeviceError
from drivers.modbus_laser import ModbusLaser, ModbusLaserConfig
from drivers.serial_laser import SerialLaser, SerialLaserConfig
from drivers.v4l2_camera import V4L2Camera, V4L2CameraConfig
from omnisort_hw.config.capture import CaptureSettings
from omnisort_hw.evaluation.lighting import score_points
from omnisort_hw.pipeline.measurement_capture import (
    CaptureSaturatedError,
    LaserSwitchError,
    NoLaserDifferenceError,
    capture_measurement,
)
from sim_backend.devices import SimCamera, SimCell, SimLaserSwitch
from tests.drivers.modbus_peer import ModbusTestServer
from tests.drivers.serial_emulator import SerialDeviceEmulator

pytestmark = pytest.mark.timeout(180)
WIDTH = 640
FRAMES = 3
COIL = 5


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Frames of the simulated camera in the order a capture grabs them: laser on/off pairs,
    then laser-off board frames; plus a sequence with the laser never on, and the truth."""
    out = tmp_path_factory.mktemp("frames")
    cell = SimCell.from_scene("sorting", seed=5, width=WIDTH, height=WIDTH)
    cam = SimCamera(cell, degraded=True, exposure_ms=6.0, pixel_format="BGR3")
    laser = SimLaserSwitch(cell)
    with cam, laser:
        laser.on()
        cam.grab(with_truth=True)
        truth = cam.last_truth
        direct = cam.direct_laser
        laser.off()
        seq = [cam.grab().image for _ in range(FRAMES)]  # board frames come first
        for _ in range(FRAMES):
            for on in (True, False):
                laser.set(on)
                seq.append(cam.grab().image)
        dark = [cam.grab().image for _ in range(3 * FRAMES)]
    cell.close()
    for name, frames in (("lit", seq), ("dark", dark)):
        (out / name).mkdir()
        for i, img in enumerate(frames):
            cv2.imwrite(str(out / name / f"f_{i:03d}.png"), img)
    return {"dir": out, "truth": truth, "direct": direct}


def file_camera(folder: Path) -> V4L2Camera:
    return V4L2Camera(
        V4L2CameraConfig(device=str(folder / "f_%03d.png"), api="images", tone_curve="linear")
    )


@pytest.fixture
def modbus() -> Iterator[ModbusTestServer]:
    server = ModbusTestServer()
    yield server
    server.stop()


def modbus_laser(server: ModbusTestServer) -> ModbusLaser:
    return ModbusLaser(ModbusLaserConfig(tcp_port=server.port, coil=COIL, timeout_s=1.0))


def test_capture_through_modbus_and_a_file_camera_finds_only_the_true_stripe(
    recorded, modbus
) -> None:
    with file_camera(recorded["dir"] / "lit") as cam, modbus_laser(modbus) as laser:
        cap = capture_measurement(cam, laser, CaptureSettings(frames=FRAMES))
        assert laser.state() is False  # put back as it was
    score = score_points(cap.stripe_px, recorded["truth"], recorded["direct"])
    assert score["laser_points"] >= 40
    assert score["spurious_points"] == 0
    rec = cap.record
    assert rec["frames"] == FRAMES and rec["frames_grabbed"] == 3 * FRAMES
    assert "source cannot tell" in rec["pixel_format"]  # a file cannot switch formats
    assert cap.board_image is not None and cap.board_image.shape == (WIDTH, WIDTH, 3)
    # the board image is the mean of the laser-off frames: less noise than one of them
    one = cv2.imread(str(recorded["dir"] / "lit" / "f_000.png")).astype(float)
    nxt = cv2.imread(str(recorded["dir"] / "lit" / "f_001.png")).astype(float)
    single_noise = np.std(one - nxt) / np.sqrt(2)
    mean_noise = np.std(cap.board_image.astype(float) - one)  # ~ single noise * sqrt(1 + 1/N)
    assert mean_noise < single_noise * np.sqrt(1 + 1 / FRAMES) * 1.1 + 0.5


def test_serial_laser_is_switched_on_and_off_for_every_pair(recorded) -> None:
    with SerialDeviceEmulator() as emu:
        laser = SerialLaser(SerialLaserConfig(port=emu.path, timeout_s=1.0))
        with file_camera(recorded["dir"] / "lit") as cam, laser:
            capture_measurement(cam, laser, CaptureSettings(frames=FRAMES))
        switches = [c for c in emu.received if c in ("LASER ON", "LASER OFF")]
    pairs = switches[1 : 1 + 2 * FRAMES]  # after the board frames' "off"
    assert pairs == ["LASER ON", "LASER OFF"] * FRAMES


def test_a_laser_that_does_not_switch_is_a_typed_error_naming_it(recorded) -> None:
    with SerialDeviceEmulator(mode="stuck") as emu:
        laser = SerialLaser(SerialLaserConfig(port=emu.path, timeout_s=1.0))
        cam = file_camera(recorded["dir"] / "lit")
        with cam, laser, pytest.raises(DeviceError) as err:
            capture_measurement(cam, laser, CaptureSettings(frames=FRAMES))
    assert emu.path in str(err.value) or emu.path in str(err.value.device)


def test_no_laser_light_in_the_images_is_a_typed_error_naming_the_laser(recorded, modbus) -> None:
    cam, laser = file_camera(recorded["dir"] / "dark"), modbus_laser(modbus)
    with cam, laser, pytest.raises(NoLaserDifferenceError) as err:
        capture_measurement(cam, laser, CaptureSettings(frames=FRAMES))
    assert err.value.device == laser.name
    assert err.value.code == "no_laser_difference"


class _ReadsBackOff(SimLaserSwitch):
    """A switch whose read-back never shows on (a broken interlock or wiring)."""

    def state(self, timeout_s: float | None = None) -> bool:
        return False


def test_read_back_that_differs_is_a_laser_switch_error() -> None:
    cell = SimCell.from_scene("sorting", seed=1, width=192, height=192)
    try:
        with SimCamera(cell, degraded=True) as cam, _ReadsBackOff(cell) as laser:
            with pytest.raises(LaserSwitchError) as err:
                capture_measurement(cam, laser, CaptureSettings(frames=1))
            assert err.value.device == laser.name
    finally:
        cell.close()


def test_a_clipped_stripe_is_re_exposed_and_a_stubborn_one_is_refused() -> None:
    cell = SimCell.from_scene("sorting", seed=2, light="saturated", width=WIDTH, height=WIDTH)
    try:
        with SimCamera(cell, degraded=True) as cam, SimLaserSwitch(cell) as laser:
            settings = CaptureSettings(frames=2)
            cap = capture_measurement(cam, laser, settings, board=False)
            tried = cap.record["stripe_exposures"]
            assert tried[0]["clipped_fraction"] > settings.clipped_limit
            assert tried[-1]["clipped_fraction"] <= settings.clipped_limit
            assert tried[-1]["exposure_ms"] < tried[0]["exposure_ms"]
            assert cam.get_exposure_ms() == pytest.approx(10.0)  # put back
            with pytest.raises(CaptureSaturatedError):
                capture_measurement(
                    cam, laser, CaptureSettings(frames=2, max_retries=0), board=False
                )
    finally:
        cell.close()


class _CoveredLaser(SimLaserSwitch):
    """A switch that reads back what it was told but whose light never reaches the scene (a
    covered aperture, a dead diode)."""

    lit = False

    def set(self, on: bool, timeout_s: float | None = None) -> None:
        self._require()
        self.lit = bool(on)

    def state(self, timeout_s: float | None = None) -> bool:
        self._require()
        return self.lit


@pytest.mark.parametrize("seed", [21, 22])
def test_a_dark_laser_through_a_real_colour_camera_is_no_laser_not_phantoms(seed: int) -> None:
    """The cell's own path, laser on/off differences, on the cluttered sorting cell through the
    colour camera's effects (crosstalk, chromatic aberration, bloom, Bayer demosaicing) with a
    laser whose light never arrives: a typed error naming the laser, not a stripe of phantoms."""
    from sim_backend.scene import load_scene, sized, with_camera_effects

    scene = with_camera_effects(sized(load_scene("sorting"), WIDTH))
    cell = SimCell.from_scene(scene, seed=seed)
    cam = SimCamera(cell, degraded=True, exposure_ms=6.0, pixel_format="BGR3")
    laser = _CoveredLaser(cell)
    try:
        with cam, laser, pytest.raises(NoLaserDifferenceError) as err:
            capture_measurement(cam, laser, CaptureSettings(frames=FRAMES), board=False)
    finally:
        cell.close()
    assert err.value.device == laser.name and "sees no laser light" in str(err.value)
