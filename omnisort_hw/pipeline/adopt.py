"""Adopt calibration files made by the command line into a cell's calibration store: the one
way a `camera.json` or `system.json` calibrated elsewhere becomes the cell's, so that a cell is
commissioned once (the CLI's plain files are refused as "no checksum" when copied into the
state directory by hand).

Each file is verified before anything is stored: it parses as the core's model; the camera
model fits the frames the cell's camera gives now (their size); the system calibration was
made with that camera model. Both are then saved through the store (checksum, the attached
camera's serial, the previous version kept in `history/`). A system file with a robot base
takes the laser-off frame it was checked with as the drift watchdog's reference, as
`register_robot` does.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from omnisort_hw.core.camera_io import camera_from_record
from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.errors import CalibrationFileError, InputError
from omnisort_hw.fileio import read_calibration_json
from omnisort_hw.pipeline.calibration_source import read_system_payload
from omnisort_hw.pipeline.calibration_store import CHECKSUM_KEY, META_KEY, CalibrationStore
from omnisort_hw.pipeline.image_files import check_image_size
from omnisort_hw.pipeline.replies import AdoptedFile, AdoptReply
from omnisort_hw.pipeline.requests import AdoptRequest


@dataclass(frozen=True)
class Adopted:
    """One file taken in: where from, where it is stored, its new checksum."""

    kind: str
    source: str
    path: str
    checksum: str


@dataclass(frozen=True)
class AdoptResult:
    """The files adopted, and whether a drift reference was taken with them."""

    files: tuple[Adopted, ...]
    drift_reference: bool

    def reply(self) -> AdoptReply:
        adopted = {
            f.kind: AdoptedFile(path=f.path, checksum=f.checksum, source=f.source)
            for f in self.files
        }
        return AdoptReply(adopted, self.drift_reference)


class AdoptRig(Protocol):
    """What adopting needs of a cell: its store, a laser-off frame, the drift reference."""

    @property
    def store(self) -> CalibrationStore: ...

    def grab_frame(self, laser: bool) -> np.ndarray: ...

    def save_drift_reference(self, image: np.ndarray) -> None: ...


def _payload(record: dict[str, Any]) -> dict[str, Any]:
    """The record without the storage keys of the store that wrote it (if one did)."""
    return {k: v for k, v in record.items() if k not in (META_KEY, CHECKSUM_KEY)}


def same_model(a: OcamModel, b: OcamModel) -> bool:
    """Whether two camera models are the same calibration (size, centre, stretch and
    polynomial equal to the digits JSON keeps)."""
    return (
        tuple(a.image_size) == tuple(b.image_size)
        and a.poly.shape == b.poly.shape
        and np.allclose(a.poly, b.poly, rtol=1e-9, atol=0.0)
        and np.allclose(a.center_uv, b.center_uv, rtol=1e-9, atol=1e-9)
        and np.allclose(a.stretch, b.stretch, rtol=1e-9, atol=1e-12)
    )


def run(rig: AdoptRig, request: AdoptRequest) -> AdoptResult:
    """Verify the request's files against the cell, then store them (see the module doc)."""
    if request.camera is None and request.system is None:
        raise InputError("adopt: give camera (a camera.json), system (a system.json) or both")
    store = rig.store
    camera_payload: dict[str, Any] | None = None
    if request.camera is not None:
        record = read_calibration_json(request.camera, "camera")
        model = camera_from_record(record, str(request.camera))
        camera_payload = _payload(record)
        camera_source = str(request.camera)
    else:
        model = store.camera_model()
        camera_source = str(store.path("camera"))
    system_payload: dict[str, Any] | None = None
    if request.system is not None:
        raw, _ = read_system_payload(request.system)
        system_payload = _payload(raw)
        calib = SystemCalibration.from_json(system_payload, source=str(request.system))
        if not same_model(calib.model, model):
            raise CalibrationFileError(
                f"{request.system}: calibrated with another camera model than {camera_source} "
                f"(image {calib.model.image_size[0]}x{calib.model.image_size[1]}, centre "
                f"{calib.model.center_uv[0]:.2f}, {calib.model.center_uv[1]:.2f} against "
                f"{model.image_size[0]}x{model.image_size[1]}, "
                f"{model.center_uv[0]:.2f}, {model.center_uv[1]:.2f}); adopt the camera.json "
                "it was calibrated with, or recalibrate"
            )
    image = rig.grab_frame(laser=False)
    check_image_size(image, model, f"{camera_source} (the cell's camera now)")
    files = []
    for kind, payload, source in (
        ("camera", camera_payload, request.camera),
        ("system", system_payload, request.system),
    ):
        if payload is None:
            continue
        path = store.save(kind, payload)
        files.append(Adopted(kind, str(source), str(path), store.read(kind).checksum))
    registered = system_payload is not None and isinstance(system_payload.get("robot_base"), dict)
    if registered:
        rig.save_drift_reference(image)
    return AdoptResult(tuple(files), registered)
