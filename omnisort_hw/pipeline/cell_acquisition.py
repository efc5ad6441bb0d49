"""What the cell's measuring commands work on: a given image file, or a measurement capture
(`measurement_capture`) with the cell's camera and laser, its images saved under the cell's
capture folder so the calibration and the log can name them.

`calibrate` (extrinsics) uses the board image (laser off, averaged) for the target's edges and
markers and the capture's stripe points; `map` the laser-light image; `locate` the board image
for colours and the laser-light image for heights. A given file serves as both, as before.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from omnisort_hw import fileio
from omnisort_hw.core.radiometry import ToneCurve
from omnisort_hw.errors import OmnisortError
from omnisort_hw.pipeline.extrinsics import image_record
from omnisort_hw.pipeline.image_files import read_image
from omnisort_hw.pipeline.measurement_capture import CaptureSettings, capture_measurement


@dataclass
class Acquired:
    """Images to measure on: `board` (edges, markers, colours), `stripe` (where the laser is
    found) and its points when a capture measured them; `record` for system.json and replies."""

    board: np.ndarray
    stripe: np.ndarray | None
    stripe_px: np.ndarray | None
    record: dict[str, Any]
    source: str
    tone: ToneCurve | None = None  # the camera's curve as the capture measured it


def _save(folder: Path, name: str, image: np.ndarray) -> dict[str, Any]:
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise OmnisortError(f"could not encode the {name} image as PNG")
    data = buf.tobytes()
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S.%fZ")
    path = folder / f"capture-{stamp}-{name}.png"
    fileio.atomic_write_bytes(path, data, keep_history=False)
    return {"path": str(path), "sha256": hashlib.sha256(data).hexdigest()}


def acquire(cell: Any, image: str | None, board: bool = True) -> Acquired:
    """The file `image`, or a measurement capture on `cell` (a `Cell`: its camera and laser
    under their locks, its capture folder, run log and `[capture]` settings)."""
    if image is not None:
        img = read_image(image)
        return Acquired(img, img, None, image_record(image), str(image))
    camera = cell._need("camera")
    laser = cell._need("laser")
    settings: CaptureSettings = getattr(cell.config, "capture", None) or CaptureSettings()
    if cell.actuation_guard is not None:
        cell.actuation_guard()
    with cell._locked(cell._camera_lock, "camera"), cell._locked(cell._laser_lock, "laser"):
        try:
            cap = capture_measurement(camera, laser, settings, cell.runlog, board=board)
        finally:
            cell._cache_laser(bool(laser.state()))
    stripe = _save(cell.capture_dir, "laser", cap.stripe_image)
    record: dict[str, Any] = {"capture": cap.record, "laser_image": stripe}
    if cap.board_image is not None:
        record.update(_save(cell.capture_dir, "board", cap.board_image))
    else:
        record.update(stripe)
    cell._prune_captures()
    board_img = cap.board_image if cap.board_image is not None else cap.stripe_image
    return Acquired(board_img, cap.stripe_image, cap.stripe_px, record, record["path"], cap.tone)
