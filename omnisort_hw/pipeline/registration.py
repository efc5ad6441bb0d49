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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw.config.sorting import RegistrationConfig
from omnisort_hw.core.cell_pictures import draw_registration
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.overlays import write_picture
from omnisort_hw.core.records import PictureReply
from omnisort_hw.core.registration import Registration, register_robot
from omnisort_hw.errors import CalibrationError, CalibrationFileError, NotAvailableError
from omnisort_hw.pipeline.cell_acquisition import frame
from omnisort_hw.pipeline.intrinsics import board_record
from omnisort_hw.pipeline.replies import RegisterReply
from omnisort_hw.pipeline.requests import RegisterRequest
from omnisort_hw.pipeline.rig import Rig
from omnisort_hw.pipeline.verdict import Verdict, graded, verdict_lines
from omnisort_hw.runlog import NullLog, RunLog

MAX_BASE_DISTANCE_MM = 10000.0
"""No robot base of a cell is farther than this from its camera (a UR10e reaches 1.3 m; the
camera sees the floor a few metres around it): farther is a wrong offset or square size."""
BASE_SIGMA_MM = (2.5, 5.0)
"""The base's 1-sigma position that passes, and beyond which it fails: every cube's position in
B carries it, and `[sorting] max_sigma_mm` (5 mm by default) skips cubes located worse."""


@dataclass
class RegisterResult:
    """A registration, its `robot_base` record, where it was saved (None: not saved) and its
    picture."""

    registration: Registration
    record: dict[str, Any]
    path: Path | None
    picture: PictureReply = field(default_factory=lambda: PictureReply())

    def verdict(self) -> Verdict:
        """The board corners' RMS as the intrinsics' are judged, and the base's sigma."""
        from omnisort_hw.pipeline.intrinsics import CORNER_RMS_PX

        reg = self.registration
        rms = graded(
            "board corner RMS",
            reg.rms_px,
            "px",
            *CORNER_RMS_PX,
            advice="is the whole board flat on the floor, in view and in focus?",
        )
        worst = max(reg.std.get("x_mm", 0.0), reg.std.get("y_mm", 0.0), reg.std.get("z_mm", 0.0))
        sigma = graded(
            "base position sigma",
            worst,
            "mm",
            *BASE_SIGMA_MM,
            advice="the board is small or far in the image: a larger board, or nearer the camera",
        )
        return Verdict("robot registration", (rms, sigma))

    def reply(self) -> RegisterReply:
        """The answer at every door: the `robot_base` record, where it was saved, the picture
        and the verdict."""
        return RegisterReply(
            robot_base=self.record,
            path=str(self.path) if self.path is not None else None,
            verdict=self.verdict(),
            **vars(self.picture),
        )

    def lines(self, with_verdict: bool = True) -> list[str]:
        """The registration in a few lines for people (the picture's legend, the CLI)."""
        x, y, z = self.record["xyz_mm"]
        r, p, w = self.record["rpy_deg"]
        std, reg = self.registration.std, self.registration
        return [
            f"robot base T_SB: xyz ({x:.1f}, {y:.1f}, {z:.1f}) mm, "
            f"rpy ({r:.2f}, {p:.2f}, {w:.2f}) deg",
            f"1-sigma: x {std['x_mm']:.2f}, y {std['y_mm']:.2f}, z {std['z_mm']:.2f} mm, "
            f"yaw {std['yaw_deg']:.3f} deg",
            f"{len(reg.corners_px)} board corners, RMS {reg.rms_px:.3f} px",
            *(verdict_lines(self.verdict()) if with_verdict else []),
        ]


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
    image = frame(rig, request.image, laser=False)
    rig.runlog.image("registration/image", image)
    reg = rig.run_logged(register_from_image, image, calib, rc, cancel=cancel, what="registration")
    distance = float(np.linalg.norm(reg.T_SB[:3, 3]))
    if not distance <= MAX_BASE_DISTANCE_MM:
        raise CalibrationError(
            f"registration: the robot base would be {distance:.0f} mm from the camera, farther "
            f"than any cell ({MAX_BASE_DISTANCE_MM:.0f} mm); check [registration] offset and "
            "square_mm (nothing was saved)"
        )
    record = robot_base_record(reg, rc, request.image or "capture", request.model)
    path = rig.save_robot_base(record, image) if request.save else None
    result = RegisterResult(reg, record, path)
    result.picture = write_picture(
        rig.picture_path("registration", request.image),
        lambda: draw_registration(image, calib, reg.corners_px, reg.T_SB, result.lines()),
    )
    return result


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


def write_robot_base(path: str | Path, record: Mapping[str, object]) -> Path:
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
