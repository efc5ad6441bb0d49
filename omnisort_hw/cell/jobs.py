"""The cell's long commands: calibrate (intrinsics, extrinsics), map, register_robot, locate
and sort, each a call into the use-case layer (`omnisort_hw.pipeline`) with the cell's
devices, calibration store, run log, compute worker and the cell file's typed record.

`CellJobs` is the cell's `jobs` (`cell.jobs.map_scene(...)`), kept apart because these are the
use cases and the rest of the cell is devices, status and motion; it sees the cell only through
`CellHost`, the members it needs. A command whose section is missing raises
`NotAvailableError` naming it.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

import numpy as np

from omnisort_hw.config.cell import CellConfig
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.errors import MotionRefusedError
from omnisort_hw.pipeline.calibration_store import CalibrationStore
from omnisort_hw.pipeline.replies import (
    AdoptReply,
    ExtrinsicsReply,
    IntrinsicsReply,
    LaserReply,
    LocateReply,
    MapReply,
    RegisterReply,
    SortReply,
)
from omnisort_hw.pipeline.requests import (
    AdoptRequest,
    CalibrateRequest,
    IntrinsicsRequest,
    LocateRequest,
    MapRequest,
    RegisterRequest,
    SortRequest,
)

if TYPE_CHECKING:
    from contextlib import AbstractContextManager

    from omnisort_hw.cell.compute_worker import ComputeWorker
    from omnisort_hw.cell.devices import Devices
    from omnisort_hw.cell.journal import JobJournal
    from omnisort_hw.cell.status_reply import CellStatus
    from omnisort_hw.cell.watchdog import DriftWatchdog
    from omnisort_hw.config.capture import CaptureSettings
    from omnisort_hw.config.sorting import RegistrationConfig
    from omnisort_hw.core.camera_model import OcamModel
    from omnisort_hw.core.radiometry import ToneCurve
    from omnisort_hw.pipeline.calibration_source import CalibrationSource
    from omnisort_hw.pipeline.sort_run import SortSession
    from omnisort_hw.runlog import RunLog


T = TypeVar("T")
log = logging.getLogger(__name__)


class CellHost(Protocol):
    """What the use cases need of their cell (`cell.Cell`): its devices, store, cell file,
    compute worker, job journal, drift watchdog and resolved sections, its run log, its camera
    and laser under their locks, and its measurement capture."""

    devices: Devices
    store: CalibrationStore
    config: CellConfig
    compute: ComputeWorker
    journal: JobJournal
    drift: DriftWatchdog
    sort_config: SortConfig | None
    registration_config: RegistrationConfig | None
    capture_dir: Path

    @property
    def runlog(self) -> RunLog: ...

    @property
    def capture_settings(self) -> CaptureSettings: ...

    def grab(self, timeout_s: float | None = None) -> Any: ...

    def live_frame(self) -> Any: ...

    def set_laser(self, on: bool) -> bool: ...

    def laser(self, on: bool | None = None) -> LaserReply: ...

    def measuring(self) -> AbstractContextManager[tuple[Any, Any]]: ...

    def prune_captures(self) -> None: ...

    def status(self) -> CellStatus: ...


class CellJobs:
    """The use cases of a cell (see the module doc): the cell's rig (`pipeline.rig.Rig`,
    `sort_run.SortRig`, `adopt.AdoptRig`) over the narrow `CellHost`."""

    def __init__(self, cell: CellHost) -> None:
        self.cell = cell

    # -- what the use cases read of the cell (and a `cell_acquisition.CaptureRig`) ---------

    @property
    def store(self) -> CalibrationStore:
        return self.cell.store

    @property
    def sort_config(self) -> SortConfig | None:
        return self.cell.sort_config

    @property
    def registration_config(self) -> RegistrationConfig | None:
        return self.cell.registration_config

    @property
    def runlog(self) -> RunLog:
        return self.cell.runlog

    @property
    def capture_dir(self) -> Path:
        return self.cell.capture_dir

    @property
    def capture_settings(self) -> CaptureSettings:
        return self.cell.capture_settings

    def measuring(self) -> AbstractContextManager[tuple[Any, Any]]:
        return self.cell.measuring()

    def prune_captures(self) -> None:
        self.cell.prune_captures()

    # -- pipeline (use cases) --------------------------------------------------------------

    def calibrate_intrinsics(
        self, request: IntrinsicsRequest, cancel: threading.Event | None = None
    ) -> IntrinsicsReply:
        """Intrinsic calibration from the request's checkerboard images, saved as camera.json.

        The images are taken to come from the camera attached now (its serial is stored).
        """
        from omnisort_hw.pipeline import intrinsics

        reply = intrinsics.run(self, request, cancel).reply()
        return replace(reply, camera_serial=self.store.expected_serial)

    def calibrate_extrinsics(
        self, request: CalibrateRequest, cancel: threading.Event | None = None
    ) -> ExtrinsicsReply:
        """Camera rotation and laser plane from one image of the calibration target (a fresh
        capture with the laser on, or the request's image), saved as system.json. The previous
        robot base pose is not carried over: it was registered with the previous camera
        rotation."""
        from omnisort_hw.pipeline import extrinsics

        return extrinsics.run(self, request, cancel).reply()

    def map_scene(self, request: MapRequest, cancel: threading.Event | None = None) -> MapReply:
        """Laser map: the stripe's pixels -> points on the laser plane (S, mm) -> segments;
        `request.points` adds the points (S, 0.1 mm) and their pixels, `request.picture`
        writes the map's picture as map_overlay.png beside system.json (one, overwritten)."""
        from omnisort_hw.pipeline import laser_map

        return laser_map.run(self, request, cancel).reply()

    def register_robot(
        self, request: RegisterRequest, cancel: threading.Event | None = None
    ) -> RegisterReply:
        """Robot base pose T_SB from the floor checkerboard in the request's image (or a
        laser-off capture), saved as `robot_base` in the store's system.json."""
        from omnisort_hw.pipeline import registration

        return registration.run(self, request, cancel).reply()

    def locate(self, request: LocateRequest, cancel: threading.Event | None = None) -> LocateReply:
        """The cubes in the request's image (or laser-off and laser-on captures), in S and B."""
        from omnisort_hw.pipeline import locate

        return locate.run(self, request, cancel).reply()

    def adopt(self, request: AdoptRequest) -> AdoptReply:
        """The CLI's camera.json and system.json, verified against this cell, as its own."""
        from omnisort_hw.pipeline import adopt

        return adopt.run(self, request).reply()

    def save_drift_reference(self, image: np.ndarray) -> None:
        self.cell.drift.save_reference(image)

    # -- what makes the cell a `pipeline.rig.Rig` ------------------------------------------

    @property
    def system_path(self) -> Path:
        return self.store.path("system")

    def arm_joints(self) -> list[float] | None:
        """The arm's last joint reading (deg) from the cell's status snapshot (no device
        traffic), None when it has none."""
        arm = self.cell.status()["devices"].get("arm") or {}
        joints = arm.get("joints_deg")
        return [float(q) for q in joints] if isinstance(joints, list) else None

    def system_calibration(self) -> SystemCalibration:
        """The verified system.json as the core's SystemCalibration."""
        rec = self.store.read("system")
        return SystemCalibration.from_json(rec.payload, source=str(rec.path))

    def camera_model(self) -> OcamModel:
        return self.store.camera_model()

    def tone_curve(self) -> ToneCurve:
        """The camera's transfer curve, undone wherever edges are located in its images (the
        extrinsic target's borders and markers); sRGB when the cell has no camera, what 8-bit
        image files hold."""
        from omnisort_hw.core.radiometry import ToneCurve

        camera = self.cell.devices.camera
        return ToneCurve.parse(camera.tone_curve if camera is not None else None)

    def laser_color(self) -> str:
        return self.cell.config.devices.laser_color

    def target_defaults(self) -> tuple[str | None, float | None, str]:
        t = self.cell.config.target
        field = "separation_mm (or [target] separation_mm in the cell file)"
        return t.kind, t.separation_mm, field

    def has_laser(self) -> bool:
        return self.cell.devices.laser is not None

    def grab_frame(self, laser: bool) -> np.ndarray:
        """A frame of the cell's camera with the laser switched to `laser` (off after)."""
        if self.cell.devices.laser is not None:
            self.cell.set_laser(laser)
        try:
            return np.asarray(self.cell.grab().image)
        finally:
            if laser and self.cell.devices.laser is not None:
                self.cell.set_laser(False)

    def dark_frame(self) -> np.ndarray:
        """A laser-off frame for the drift watchdog, the laser left as it was: a periodic
        check must not switch off a laser an operator switched on (unless the cell now refuses
        to switch it on: then it stays off, and why is logged)."""
        was_on = self.cell.devices.laser is not None and self.cell.laser().on
        try:
            return self.grab_frame(laser=False)
        finally:
            if was_on:
                try:
                    self.cell.set_laser(True)
                except Exception as exc:  # a refusal or a device error: leave it off, say why
                    log.warning("the laser stays off after the drift check: %s", exc)

    @property
    def views_dir(self) -> Path:
        """Where the intrinsics' views taken from the live camera are kept (beside the store's
        files)."""
        return self.store.path("camera").parent / "views"

    def live_frame(self) -> np.ndarray:
        """A fresh frame for a screen, the laser as it is (`cell.Cell.live_frame`)."""
        return np.asarray(self.cell.live_frame().image)

    def run_logged(
        self,
        fn: Callable[..., T],
        *args: Any,
        cancel: threading.Event | None = None,
        what: str = "job",
        **kwargs: Any,
    ) -> T:
        """In the compute worker, its run-log calls replayed on the cell's run log."""
        return self.cell.compute.call_logged(
            fn, self.runlog, *args, cancel=cancel, what=what, **kwargs
        )

    def save_camera(self, model: OcamModel, record: Mapping[str, object]) -> Path:
        from omnisort_hw.core.camera_io import camera_record

        return self.store.save_camera(camera_record(model, **record))

    def save_system(self, payload: Mapping[str, object]) -> Path:
        return self.store.save_system(dict(payload))

    def save_robot_base(self, record: Mapping[str, object], image: np.ndarray) -> Path:
        """Into the store's system.json; `image` becomes the drift watchdog's reference."""
        payload = dict(self.store.load_system())
        payload["robot_base"] = dict(record)
        path = self.store.save_system(payload)
        self.cell.drift.save_reference(image)
        return path

    def picture_path(self, kind: str, image: str | None) -> Path:
        """One per kind beside system.json, replaced by the next."""
        return self.store.path("system").with_name(f"{kind}_overlay.png")

    def sort(
        self,
        request: SortRequest,
        cancel: threading.Event,
        progress: Callable[[dict[str, Any]], None] | None = None,
    ) -> SortReply:
        """Locate, pick and place every object by colour until done, `max_objects` or cancel;
        gated by the calibration store and the drift watchdog (`pipeline.sort_run`)."""
        from omnisort_hw.pipeline import sort_run

        return sort_run.run(self, request, cancel, progress).reply()

    # -- and a `pipeline.sort_run.SortRig` -------------------------------------------------

    def laser_off(self) -> None:
        """Switch the laser off (how a sort's capture ends)."""
        self.cell.set_laser(False)

    def calibration_source(self) -> CalibrationSource:
        from omnisort_hw.pipeline.calibration_source import StoreCalibration

        return StoreCalibration(self.store)

    def check_drift(self) -> None:
        self.cell.drift.before_sort()

    @contextmanager
    def sorting(self, request: SortRequest) -> Iterator[SortSession]:
        """The cell's devices, connected since start, through its locks; its compute worker
        and its measurement capture (the service's job runner journals the job itself)."""
        from omnisort_hw.pipeline.sort_capture import sort_capture_for
        from omnisort_hw.pipeline.sort_run import SortSession

        arm = self.cell.devices.arm
        if self.cell.devices.camera is None or arm is None:
            raise MotionRefusedError("sort: the cell needs a camera and an arm")
        laser = _CellLaser(self.cell) if self.cell.devices.laser is not None else None
        yield SortSession(
            _CellCamera(self.cell),  # type: ignore[arg-type]
            laser,  # type: ignore[arg-type]
            arm,
            self.cell.journal,
            compute=self.cell.compute,
            acquire=sort_capture_for(self, self.laser_off if laser is not None else None),
        )


class _CellCamera:
    """The cell's camera through the cell (its lock and its run log)."""

    def __init__(self, cell: CellHost) -> None:
        self.cell = cell

    def grab(self, timeout_s: float | None = None) -> Any:
        return self.cell.grab(timeout_s)


class _CellLaser:
    """The cell's laser switch through the cell (its lock and its status cache)."""

    def __init__(self, cell: CellHost) -> None:
        self.cell = cell

    def on(self) -> None:
        self.cell.set_laser(True)

    def off(self) -> None:
        self.cell.set_laser(False)
