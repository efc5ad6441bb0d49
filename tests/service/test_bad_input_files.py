"""The bad-input table (docs/bad_inputs.md) through the service and `omnisort ctl`: a bad file
is that request's typed error naming the file; the cell stays `idle` (it used to latch `fault`
on an empty image, refusing every later job until `reset`), and the next job runs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.bad_files import BAD_IMAGES, doc_rows, good_calibration, make_bad
from tests.service.conftest import Harness

pytestmark = pytest.mark.timeout(120)

# command -> the request's arguments with the bad file put in (`locate` and `register_robot`
# need the cell file's [sorting] and [registration], which this cell has not: the CLI rows
# cover them)
SERVICE_ROWS = {
    "map": lambda path: {"image": str(path)},
    "check": lambda path: {"image": str(path)},
    "calibrate extrinsics": lambda path: {
        "what": "extrinsics",
        "image": str(path),
        "target": "two-sided",
        "separation_mm": 1084.5,
    },
}


def _calibrate(service: Harness) -> None:
    """A calibration valid in every field, so that a request reaches its image."""
    camera, system = good_calibration()
    service.cell.store.save_camera(camera)
    service.cell.store.save_system(system)


@pytest.mark.parametrize("kind", sorted(BAD_IMAGES))
def test_a_bad_image_is_the_requests_error_and_the_cell_stays_ready(
    service: Harness, tmp_path: Path, kind: str
) -> None:
    path, words = make_bad(kind, tmp_path, "bad.png")
    _calibrate(service)
    with service.client(timeout_s=60) as c:
        for command, args in SERVICE_ROWS.items():
            reply = c.call(command.split()[0], args(path))
            assert not reply["ok"], (command, reply)
            error = reply["error"]
            assert error["code"] == "bad_input", (command, error)
            assert str(path) in error["message"] and words in error["message"], (command, error)
            assert c.call("status")["result"]["state"] == "idle", command
        # a folder of intrinsics views holding the bad file
        views = tmp_path / "views"
        views.mkdir()
        if path.is_file():  # a folder among the views is not an image: skipped
            path.rename(views / path.name)
            reply = c.call(
                "calibrate", {"what": "intrinsics", "folder": str(views), "square_mm": 30}
            )
            assert reply["error"]["code"] == "bad_input", reply
            assert str(views / path.name) in reply["error"]["message"], reply
        assert c.call("status")["result"]["state"] == "idle"
        assert c.call("move", {"joints_deg": [5, 0, 0, 0, 0, 0]})["ok"]  # nothing latched


@pytest.mark.parametrize("kind", sorted(BAD_IMAGES))
def test_ctl_prints_the_typed_error_and_exits_1(
    service: Harness, tmp_path: Path, kind: str
) -> None:
    path, words = make_bad(kind, tmp_path, "bad.png")
    _calibrate(service)
    port = str(service.running.port)
    base = [sys.executable, "-m", "omnisort_hw.cli", "ctl", "--port", port, "--json"]
    proc = subprocess.run(
        [*base, "map", f"image={path}"], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    error = json.loads(proc.stdout)["error"]
    assert (
        error["code"] == "bad_input" and str(path) in error["message"] and words in error["message"]
    )
    status = subprocess.run([*base, "status"], capture_output=True, text=True, timeout=60)
    assert json.loads(status.stdout)["result"]["state"] == "idle"


def test_the_doc_lists_every_row_the_tests_try() -> None:
    rows = doc_rows()
    for kind in BAD_IMAGES:
        assert ("service", kind) in rows, kind
    for kind in BAD_IMAGES:
        assert ("ctl", kind) in rows, kind


@pytest.mark.parametrize(
    ("make", "words"),
    [
        (lambda p: p.write_bytes(b"not a folder"), "is a file"),
        (lambda p: None, "no such folder"),
        (lambda p: p.mkdir(), "no images"),
    ],
)
def test_a_bad_views_folder_is_the_requests_error(
    service: Harness, tmp_path: Path, make: object, words: str
) -> None:
    folder = tmp_path / "views"
    make(folder)  # type: ignore[operator]
    with service.client(timeout_s=60) as c:
        args = {"what": "intrinsics", "folder": str(folder), "square_mm": 30}
        reply = c.call("calibrate", args)
        state = c.call("status")["result"]["state"]
    assert reply["error"]["code"] == "bad_input", reply
    assert str(folder) in reply["error"]["message"] and words in reply["error"]["message"]
    assert state == "idle"
