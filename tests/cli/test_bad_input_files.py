"""The bad-input table (docs/bad_inputs.md) through the command line: every command that reads
an image or a calibration file refuses each bad kind with a typed error naming the file, as
JSON for `--json`, and no traceback. In process (`main(argv)`): each row is cheap."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from omnisort_hw.cli import main
from tests.bad_files import BAD_CALIBRATIONS, BAD_IMAGES, doc_rows, good_calibration, make_bad

pytestmark = pytest.mark.timeout(60)

SIZE = 640
IMAGE_COMMANDS = {
    "intrinsics calibrate": "intrinsics calibrate {image} --square 30 --out {out}/camera.json",
    "extrinsics calibrate": "extrinsics calibrate {image} --camera {camera} --target two-sided "
    "--separation 1084.5 --out {out}/system.json",
    "map": "map {image} --system {system}",
    "check": "check {image} --system {system}",
    "register-robot": "register-robot {image} --system {system} --square 40 --offset 0,0,0,0,0,0",
    "locate": "locate {image} --system {system}",
}
CALIBRATION_COMMANDS = {
    "extrinsics calibrate": ("camera", IMAGE_COMMANDS["extrinsics calibrate"]),
    "map": ("system", IMAGE_COMMANDS["map"]),
    "check": ("system", IMAGE_COMMANDS["check"]),
    "register-robot": ("system", IMAGE_COMMANDS["register-robot"]),
    "locate": ("system", IMAGE_COMMANDS["locate"]),
}


def _good_files(folder: Path) -> dict[str, Path]:
    camera_rec, system_rec = good_calibration(SIZE)
    camera = folder / "camera.json"
    camera.write_text(json.dumps(camera_rec))
    system = folder / "system.json"
    system.write_text(json.dumps(system_rec))
    image = folder / "scene.png"
    assert cv2.imwrite(str(image), np.zeros((SIZE, SIZE, 3), np.uint8))
    out = folder / "out"
    out.mkdir()
    return {"camera": camera, "system": system, "image": image, "out": out}


def _run(template: str, files: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> dict:
    argv = [*template.format(**files).split(), "--json"]
    code = main(argv)
    captured = capsys.readouterr()
    assert code == 2, (argv, captured)
    assert "Traceback" not in captured.err
    return dict(json.loads(captured.out)["error"])


@pytest.mark.parametrize("kind", sorted(BAD_IMAGES))
@pytest.mark.parametrize("command", sorted(IMAGE_COMMANDS))
def test_a_bad_image_is_a_typed_error_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str, kind: str
) -> None:
    files = _good_files(tmp_path)
    files["image"], words = make_bad(kind, tmp_path, "bad.png")
    error = _run(IMAGE_COMMANDS[command], files, capsys)
    assert error["code"] == "bad_input", error
    assert str(files["image"]) in error["message"] and words in error["message"], error
    assert list(files["out"].iterdir()) == []


@pytest.mark.parametrize("kind", sorted(BAD_CALIBRATIONS))
@pytest.mark.parametrize("command", sorted(CALIBRATION_COMMANDS))
def test_a_bad_calibration_file_is_a_typed_error_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str, kind: str
) -> None:
    which, template = CALIBRATION_COMMANDS[command]
    files = _good_files(tmp_path)
    files[which], words = make_bad(kind, tmp_path, f"bad-{which}.json")
    error = _run(template, files, capsys)
    assert error["code"] == "bad_calibration_file", error
    assert str(files[which]) in error["message"] and words in error["message"], error
    assert list(files["out"].iterdir()) == []


def test_an_output_the_system_cannot_create_is_refused_before_the_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """/proc refuses new files even to root, whose permission bits say it may write: the
    check creates a file to know. The images do not exist: nothing was read first."""
    with pytest.raises(SystemExit) as info:
        main(["intrinsics", "calibrate", "a.png", "--square", "30", "--out", "/proc/x/cam.json"])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "/proc is not writable" in err and "/proc/x/cam.json" in err, err


def test_a_reader_that_goes_away_ends_the_command_quietly() -> None:
    """`omnisort ... | head -1`: stdout is a pipe whose reader has gone (its read end is
    closed before the command starts, so every write fails): exit 141 as a Unix tool
    killed by SIGPIPE, and nothing on stderr."""
    import os
    import subprocess
    import sys

    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "omnisort_hw.cli", "devices", "list", "--json"],
            stdout=write_end,
            stderr=subprocess.PIPE,
            text=True,
            timeout=60,
        )
    finally:
        os.close(write_end)
    assert proc.returncode == 141 and proc.stderr == "", proc.stderr


def test_the_doc_lists_every_row_the_tests_try() -> None:
    rows = doc_rows()
    for kind in BAD_IMAGES:
        assert ("CLI", kind) in rows, kind
    for kind in BAD_CALIBRATIONS:
        assert ("CLI", kind) in rows, kind


@pytest.mark.parametrize("square", ["1e9", "0", "-5", "0.01", "5000", "nan"])
@pytest.mark.parametrize("command", ["intrinsics calibrate", "register-robot"])
def test_a_square_no_board_can_have_is_refused_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str, square: str
) -> None:
    """`--square 1e9` calibrated and put the robot base 3e10 mm away, exit 0."""
    files = _good_files(tmp_path)
    template = IMAGE_COMMANDS[command].replace("--square 30", "").replace("--square 40", "")
    error = _run(f"{template} --square {square}", files, capsys)
    assert error["code"] == "bad_input", error
    message = error["message"]
    assert "--square" in message and ("1..1000 mm" in message or "1 to 1000 mm" in message), error
    assert json.loads(files["system"].read_text()).get("robot_base") == {
        "matrix": np.eye(4).tolist()
    }


def test_a_disk_that_fills_during_the_write_is_a_typed_error_and_leaves_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """No check before the work can see a disk fill up: the write's OSError becomes the
    command's typed error with the path and the OS's words, the old file stays whole and no
    temp file is left."""
    import errno
    import os

    from omnisort_hw import fileio

    files = _good_files(tmp_path)
    out = tmp_path / "calib_results.txt"
    out.write_text("the previous export\n")
    real_fdopen = os.fdopen

    def full_disk(fd: int, *args: object, **kwargs: object) -> object:
        handle = real_fdopen(fd, *args, **kwargs)  # type: ignore[call-overload]

        def write(data: bytes) -> int:  # the destination check's empty probe still fits
            if data:
                raise OSError(errno.ENOSPC, "No space left on device", str(out))
            return 0

        handle.write = write
        return handle

    monkeypatch.setattr(fileio.os, "fdopen", full_disk)
    code = main(["intrinsics", "export", str(files["camera"]), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert "[io_error]" in err and "ENOSPC" in err and str(out) in err, err
    assert out.read_text() == "the previous export\n"
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []
