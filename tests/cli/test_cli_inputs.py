"""Bad input at the command line: refused with a typed, named error before any work starts,
and as JSON on stdout for `--json` commands. In process (`main(argv)`), so each case is cheap."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from omnisort_hw.cli import main
from omnisort_hw.core.camera_io import save_camera_json
from omnisort_hw.core.camera_model import OcamModel


def test_an_output_that_is_a_folder_is_refused_before_the_calibration_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """argparse checks `--out` while parsing: no image is read (the images do not even
    exist), so the refusal cannot come after minutes of work."""
    folder = tmp_path / "calib"
    folder.mkdir()
    argv = ["intrinsics", "calibrate", str(tmp_path / "missing.png"), "--out", str(folder)]
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "--out" in err and f"{folder} is a folder" in err, err
    assert list(folder.iterdir()) == []


def test_an_output_under_a_file_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    blocker = tmp_path / "notes.txt"
    blocker.write_text("x")
    argv = ["extrinsics", "calibrate", "x.png", "--camera", "c.json", "--separation", "1292.4"]
    with pytest.raises(SystemExit):
        main([*argv, "--out", str(blocker / "system.json")])
    assert f"{blocker} is not a folder" in capsys.readouterr().err


def test_a_json_command_reports_its_failure_as_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A NaN in camera.json (Python's json reads it) is a typed error naming the file and
    the field, on stderr and, because of `--json`, as the service's error shape on stdout."""
    camera = save_camera_json(tmp_path / "camera.json", OcamModel.equidistant(640, 640, 185.0))
    data = json.loads(camera.read_text())
    data["poly"][1] = float("nan")
    camera.write_text(json.dumps(data))
    image = tmp_path / "target.png"
    import cv2

    assert cv2.imwrite(str(image), np.zeros((640, 640, 3), np.uint8))
    argv = ["extrinsics", "calibrate", str(image), "--camera", str(camera)]
    argv += ["--target", "two-sided", "--separation", "1292.4"]
    argv += ["--out", str(tmp_path / "system.json"), "--json"]
    code = main(argv)
    out = capsys.readouterr()
    assert code != 0
    doc = json.loads(out.out)
    assert doc["ok"] is False and doc["error"]["code"] == "bad_calibration_file", doc
    assert str(camera) in doc["error"]["message"] and "'poly'" in doc["error"]["message"]
    assert doc["error"]["message"] in out.err
    assert not (tmp_path / "system.json").exists()


def test_locate_without_a_registration_says_so_not_motion_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Locating moves nothing: a system.json without robot_base is `not_registered`, with
    the command that fixes it."""
    import cv2

    from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration

    angles = dict.fromkeys(
        ("cam_roll_deg", "cam_pitch_deg", "cam_yaw_deg", "laser_roll_deg", "laser_pitch_deg"),
        0.0,
    )
    calib = SystemCalibration.from_angles(
        OcamModel.equidistant(640, 640, 185.0), {**angles, "laser_distance_mm": 950.0}, "truth"
    )
    system = tmp_path / "system.json"
    system.write_text(json.dumps(calib.to_json()))
    image = tmp_path / "cell.png"
    assert cv2.imwrite(str(image), np.zeros((640, 640, 3), np.uint8))
    code = main(["locate", str(image), "--system", str(system), "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert code == 2 and doc["error"]["code"] == "not_registered", doc
    assert "register-robot" in doc["error"]["message"] and str(system) in doc["error"]["message"]


def test_an_output_folder_that_is_a_file_is_refused_before_rendering(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    blocker = tmp_path / "views"
    blocker.write_text("not a folder")
    with pytest.raises(SystemExit):
        main(["sim", "checkerboard-views", "--out", str(blocker)])
    assert f"{blocker} is a file, not a folder" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["demo", "--out", str(blocker / "demo")])
    assert f"{blocker} is not a folder" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("content", "why"),
    [(b"\xff\xfe\x00binary", "cannot be read"), (b"[1, 2]", "expected a table of colours")],
)
def test_a_colour_table_that_is_not_one_is_a_config_error(
    tmp_path: Path, content: bytes, why: str
) -> None:
    from omnisort_hw.core.cube_location import ColorTable
    from omnisort_hw.errors import ConfigError

    path = tmp_path / "colors.json"
    path.write_bytes(content)
    with pytest.raises(ConfigError, match=why) as info:
        ColorTable.load(path)
    assert str(path) in str(info.value)


def test_a_json_command_refused_while_parsing_still_prints_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "out"
    folder.mkdir()
    with pytest.raises(SystemExit):
        main(["intrinsics", "calibrate", "a.png", "--square", "20", "--out", str(folder), "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert doc["ok"] is False and doc["error"]["code"] == "bad_input"
    assert f"{folder} is a folder" in doc["error"]["message"]


def test_a_picture_that_cannot_be_written_costs_only_the_picture(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The calibration is the result: a folder where its picture should go is a warning, and
    system.json is written and reported."""
    from omnisort_hw.core.overlays import write_picture

    blocked = tmp_path / "system_overlay.png"
    blocked.mkdir()
    out = write_picture(blocked, lambda: np.zeros((4, 4, 3), np.uint8))
    assert out.overlay_png is None and str(blocked) in (out.overlay_problem or "")

    def broken() -> np.ndarray:
        raise IndexError("empty stripe")

    out = write_picture(tmp_path / "map_overlay.png", broken)
    assert out.overlay_png is None and "IndexError: empty stripe" in (out.overlay_problem or "")
    assert not (tmp_path / "map_overlay.png").exists()
