"""Robot registration: the robot base pose T_SB from the floor checkerboard in one image.

One use case for the CLI (`omnisort register-robot`) and the service (`register_robot`),
`run(rig, RegisterRequest)`, and a step of the sorting run (`Sorter.locate(register=True)`):
the core's `register_robot` with the
`[registration]` record, the run-log entries, the `robot_base` record stored in system.json,
and writing it into a system.json file.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw.config.sorting import RegistrationConfig
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.registration import Registration, register_robot
from omnisort_hw.errors import CalibrationFileError, NotAvailableError
from omnisort_hw.pipeline.intrinsics import board_record
from omnisort_hw.pipeline.requests import RegisterRequest
from omnisort_hw.pipeline.rig import Rig
from omnisort_hw.runlog import NullLog, RunLog


@dataclass
class RegisterResult:
    """A registration, its `robot_base` record and where it was saved (None: not saved)."""

    registration: Registration
    record: dict[str, Any]
    path: Path | None


def run(
    rig: Rig, request: RegisterRequest, cancel: threading.Event | None = None
) -> RegisterResult:
    """T_SB from the floor board in the request's image (or a laser-off frame) with the rig's
    `[registration]`, saved into its system.json unless the request says not to."""
    rc = rig.registration_config
    if rc is None:
        raise NotAvailableError(
            "the robot registration needs a [registration] section in the cell configuration "
            "(board, square_mm, offset = [X, Y, Z, RX, RY, RZ] of the board in B)"
        )
    calib = rig.system_calibration()
    image = rig.frame(request.image, laser=False)
    rig.runlog.image("registration/image", image)
    reg = rig.run_logged(register_from_image, image, calib, rc, cancel=cancel, what="registration")
    record = robot_base_record(reg, rc, request.image or "capture", request.model)
    path = rig.save_robot_base(record, image) if request.save else None
    return RegisterResult(reg, record, path)


def register_from_image(
    image: np.ndarray, calib: SystemCalibration, rc: RegistrationConfig, log: RunLog = NullLog
) -> Registration:
    """T_SB from the floor board seen in `image` (laser off), logged to `log`."""
    reg = register_robot(
        image,
        calib.model,
        calib.R_SC,
        rc.board,
        rc.T_B_board,
        rc.tilt_prior(calib),
        rc.camera_height_mm,
    )
    log_registration(log, reg)
    return reg


def robot_base_record(
    reg: Registration, rc: RegistrationConfig, image: str, model: str | None = None
) -> dict[str, Any]:
    """The `robot_base` record of system.json: the pose, its 1-sigma, the board and its offset."""
    record = reg.record(model)
    record["offset"] = list(rc.offset)
    record["board"] = board_record(rc.board)
    record["image"] = image
    return record


def log_registration(log: RunLog, reg: Registration) -> None:
    """Board corners (image), board pose and T_SB (3D) of a registration."""
    log.points2d("registration/image/corners", reg.corners_px, color=(0, 200, 0), radius=2)
    log.points2d("registration/image/first_corner", reg.corners_px[:1], color=(255, 0, 0), radius=5)
    log.pose("registration/board_S", reg.T_S_board)
    log.pose("registration/T_SB", reg.T_SB)
    log.scalar("registration/rms_px", reg.rms_px)


def write_robot_base(path: str | Path, record: Mapping[str, Any]) -> Path:
    """Put `robot_base` into a system.json (atomically, previous version kept).

    A file written by the calibration store (with a checksum) is re-saved through the store so
    its checksum stays valid; a plain file is rewritten as JSON.
    """
    from omnisort_hw import fileio

    p = Path(path)
    raw = fileio.read_calibration_json(p, "system")
    if "checksum" in raw:
        from omnisort_hw.pipeline.calibration_store import CalibrationStore, read_calibration_file

        rec = read_calibration_file(p, "system")
        if p.name != "system.json":
            raise CalibrationFileError(f"{p}: a store file must be named system.json")
        payload = dict(rec.payload)
        payload["robot_base"] = dict(record)
        return CalibrationStore(state_dir=p.parent).save_system(payload, rec.camera_serial)
    raw["robot_base"] = dict(record)
    return fileio.atomic_write_json(p, raw, keep_history=True)
