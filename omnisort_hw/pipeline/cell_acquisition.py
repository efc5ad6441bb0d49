"""What the cell's measuring commands work on: a given image file, or a measurement capture
(`measurement_capture`) with the cell's camera and laser, its images saved under the cell's
capture folder so the calibration and the log can name them.

`frame` is the same for one frame (register, check, locate without the laser).
`calibrate` (extrinsics) uses the board image (laser off, averaged) for the target's edges and
markers and the capture's stripe points; `map` the laser-light image; `locate` the board image
for colours and the laser-light image for heights. A given file serves as both, as before.
"""

from __future__ import annotations

import hashlib
from contextlib import AbstractContextManager
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np

from omnisort_hw import fileio
from omnisort_hw.config.capture import CaptureSettings
from omnisort_hw.core.radiometry import ToneCurve
from omnisort_hw.errors import OmnisortError
from omnisort_hw.pipeline.image_files import image_record, read_image
from omnisort_hw.pipeline.measurement_capture import capture_measurement
from omnisort_hw.runlog import RunLog


class CaptureRig(Protocol):
    """What a measurement capture needs of a cell (`cell.Cell` is one): its camera and laser
    held for the capture, where the images go, the `[capture]` settings and the run log."""

    @property
    def capture_dir(self) -> Path:
        """Where the capture's images are kept."""
        ...

    @property
    def runlog(self) -> RunLog: ...

    @property
    def capture_settings(self) -> CaptureSettings: ...

    def measuring(self) -> AbstractContextManager[tuple[Any, Any]]:
        """(camera, laser), both held for this capture alone; refuses when nothing may
        actuate; the laser's state is read back when it ends."""
        ...

    def prune_captures(self) -> None: ...

    def laser_color(self) -> str:
        """The laser's colour (`[laser] color`)."""
        ...


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


class FrameRig(Protocol):
    """A rig that gives one frame of its camera (`rig.Rig.grab_frame`)."""

    def grab_frame(self, laser: bool) -> np.ndarray: ...


def frame(rig: FrameRig, image: str | None, laser: bool) -> np.ndarray:
    """The one way a request's "an image file, or omitted: a capture" becomes one frame: the
    file `image`, else a frame of the rig's camera with its laser at `laser`. (`acquire` is
    the same for a measurement: averaged board frames and the laser's on/off difference.)"""
    return read_image(image) if image is not None else rig.grab_frame(laser)


def acquire(rig: CaptureRig, image: str | None, board: bool = True) -> Acquired:
    """The file `image`, or a measurement capture on `rig` (its camera and laser, its capture
    folder, run log and `[capture]` settings)."""
    if image is not None:
        img = read_image(image)
        return Acquired(img, img, None, image_record(image), str(image))
    with rig.measuring() as (camera, laser):
        cap = capture_measurement(
            camera, laser, rig.capture_settings, rig.runlog, board=board, color=rig.laser_color()
        )
    stripe = _save(rig.capture_dir, "laser", cap.stripe_image)
    record: dict[str, Any] = {"capture": cap.record, "laser_image": stripe}
    if cap.board_image is not None:
        record.update(_save(rig.capture_dir, "board", cap.board_image))
    else:
        record.update(stripe)
    rig.prune_captures()
    board_img = next(
        i for i in (cap.board_image, cap.scene_image, cap.stripe_image) if i is not None
    )
    return Acquired(board_img, cap.stripe_image, cap.stripe_px, record, record["path"], cap.tone)
