"""`adopt`: the CLI's camera.json and system.json become the cell's through one verified
command, so a cell calibrated on the command line is not calibrated a second time. A file
copied into the state directory by hand is refused (no checksum) with the command named."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from tests.bad_files import good_calibration
from tests.service.conftest import Harness

pytestmark = pytest.mark.timeout(60)

FRAME = (64, 48)  # the fake camera's frames (width, height)


def _cli_files(folder: Path, width: int = FRAME[0], height: int = FRAME[1]) -> tuple[Path, Path]:
    """camera.json and a registered system.json as the CLI writes them: plain JSON."""
    folder.mkdir(parents=True, exist_ok=True)
    camera, system = good_calibration(width, height, fov_deg=170.0)  # fits 64x48
    paths = folder / "camera.json", folder / "system.json"
    paths[0].write_text(json.dumps(camera))
    paths[1].write_text(json.dumps(system))
    return paths


def test_cli_files_copied_by_hand_are_refused_and_adopt_takes_them(
    service: Harness, tmp_path: Path
) -> None:
    camera, system = _cli_files(tmp_path / "cli")
    state = service.cell.store.state_dir
    shutil.copy(system, Path(state) / "system.json")
    health = service.cell.store.check("system")
    assert health.health == "corrupt" and "ctl adopt" in health.message, health
    with service.client() as c:
        reply = c.call("adopt", {"camera": str(camera), "system": str(system)})
        assert reply["ok"], reply
        status = c.call("status")["result"]
    adopted = reply["result"]["adopted"]
    assert adopted["system"]["from"] == str(system) and adopted["camera"]["from"] == str(camera)
    assert reply["result"]["drift_reference"] is True
    assert status["state"] == "idle"
    assert status["calibration"]["motion_allowed"] is True, status["calibration"]
    assert status["calibration"]["files"]["system"]["health"] == "ok"
    # the store's record holds the CLI's calibration, key for key, and the previous versions
    stored = service.cell.store.load_system()
    assert stored["laser_plane"] == json.loads(system.read_text())["laser_plane"]
    assert len(service.cell.store.history("system")) >= 1
    assert len(service.cell.store.history("camera")) >= 1


def test_a_system_made_with_another_camera_model_is_refused_and_nothing_stored(
    service: Harness, tmp_path: Path
) -> None:
    camera, _ = _cli_files(tmp_path / "a")
    _, other_system = _cli_files(tmp_path / "b", FRAME[0] * 2, FRAME[1] * 2)
    before = service.cell.store.path("camera").read_bytes()
    with service.client() as c:
        reply = c.call("adopt", {"camera": str(camera), "system": str(other_system)})
        state = c.call("status")["result"]["state"]
    assert reply["error"]["code"] == "bad_calibration_file", reply
    assert str(other_system) in reply["error"]["message"]
    assert "another camera model" in reply["error"]["message"]
    assert service.cell.store.path("camera").read_bytes() == before
    assert state == "idle"


def test_a_camera_model_for_frames_of_another_size_is_refused(
    service: Harness, tmp_path: Path
) -> None:
    camera, system = _cli_files(tmp_path / "big", 640, 480)
    before = service.cell.store.path("system").read_bytes()
    with service.client() as c:
        reply = c.call("adopt", {"camera": str(camera), "system": str(system)})
    assert reply["error"]["code"] == "bad_input", reply
    assert "640x480" in reply["error"]["message"] and "64x48" in reply["error"]["message"]
    assert service.cell.store.path("system").read_bytes() == before


def test_adopt_with_nothing_to_adopt_names_the_arguments(service: Harness) -> None:
    with service.client() as c:
        reply = c.call("adopt", {})
    assert reply["error"]["code"] == "bad_input"
    assert "camera" in reply["error"]["message"] and "system" in reply["error"]["message"]
