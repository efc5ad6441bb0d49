"""The bad files of the bad-input table (docs/bad_inputs.md): each kind made on the spot, so
every door (CLI, `ctl`, the service) is tried with the same bytes."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "bad_inputs.md"


def _png() -> bytes:
    ok, buf = cv2.imencode(".png", np.full((64, 64, 3), 128, np.uint8))
    assert ok
    return buf.tobytes()


def _write(data: bytes) -> Callable[[Path], Path]:
    def make(path: Path) -> Path:
        path.write_bytes(data)
        return path

    return make


def _folder(path: Path) -> Path:
    path.mkdir()
    return path


def _missing(path: Path) -> Path:
    return path


# kind -> (what the message must say, how the file is made at the given path)
BAD_IMAGES: dict[str, tuple[str, Callable[[Path], Path]]] = {
    "empty image": ("empty", _write(b"")),
    "truncated image": ("truncated", _write(_png()[:200])),
    "text as image": ("not a readable image", _write(b"this is not a picture\n")),
    "folder as image": ("is a folder", _folder),
    "missing image": ("no such image file", _missing),
}

BAD_CALIBRATIONS: dict[str, tuple[str, Callable[[Path], Path]]] = {
    "empty calibration": ("empty", _write(b"")),
    "image as calibration": ("not a readable JSON", _write(_png())),
    "truncated calibration": ("not a readable JSON", _write(b'{"poly": [1, 2')),
    "list as calibration": ("not a JSON object", _write(b"[1, 2]")),
    "folder as calibration": ("is a folder", _folder),
    "missing calibration": ("not found", _missing),
}


def good_calibration(
    size: int = 640, height: int | None = None, fov_deg: float = 185.0
) -> tuple[dict, dict]:
    """A camera.json and a registered system.json record, valid in every field, so that a
    command reaches the file under test."""
    from omnisort_hw.core.camera_io import camera_record
    from omnisort_hw.core.camera_model import OcamModel
    from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration

    model = OcamModel.equidistant(size, height or size, fov_deg)
    angles = dict.fromkeys(
        ("cam_roll_deg", "cam_pitch_deg", "cam_yaw_deg", "laser_roll_deg", "laser_pitch_deg"),
        0.0,
    )
    calib = SystemCalibration.from_angles(model, {**angles, "laser_distance_mm": 950.0}, "t")
    system = {**calib.to_json(), "robot_base": {"matrix": np.eye(4).tolist()}}
    return camera_record(model), system


def make_bad(kind: str, folder: Path, name: str) -> tuple[Path, str]:
    """The bad file of `kind` as `folder/name`, and the words its error must contain."""
    table = BAD_IMAGES if kind in BAD_IMAGES else BAD_CALIBRATIONS
    words, make = table[kind]
    return make(folder / name), words


def doc_rows() -> set[tuple[str, str]]:
    """(door, kind) of each row of the table in docs/bad_inputs.md."""
    rows = set()
    for line in DOC.read_text().splitlines():
        cells = [c.strip().strip("`") for c in line.strip().strip("|").split("|")]
        if len(cells) >= 4 and cells[0] in ("CLI", "ctl", "service"):
            rows.add((cells[0], cells[1]))
    return rows
