"""The CLI's rig (`pipeline.rig.Rig`): explicit files, and the cell file's devices opened for
one capture, so a command runs the service's use case on what its flags name.

What it reads: system.json (checksum verified where it has one), camera.json, the cell file's
`[target]`, `[sorting]`, `[registration]`, `[capture]` and `[storage]`; what it writes: the
file the command names (`--out`, the system.json it registers into, the map's picture) and,
for a capture, its images in `captures/` beside that system.json, as the service keeps them. The
use cases run in this process (no compute worker), so a progress callback reaches the
terminal.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator, Mapping
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from omnisort_hw import fileio
from omnisort_hw.config.capture import CaptureSettings
from omnisort_hw.config.cell import CellConfig, load_cell_config
from omnisort_hw.config.sorting import RegistrationConfig
from omnisort_hw.config.watchdog import WatchdogConfig
from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.core.radiometry import SRGB, ToneCurve
from omnisort_hw.errors import ConfigError, InputError
from omnisort_hw.pipeline.image_files import read_image
from omnisort_hw.pipeline.requests import SortRequest
from omnisort_hw.runlog import NullLog, RunLog

if TYPE_CHECKING:
    from omnisort_hw.cell.devices import Devices
    from omnisort_hw.pipeline.calibration_source import CalibrationSource
    from omnisort_hw.pipeline.calibration_store import CalibrationStore
    from omnisort_hw.pipeline.sort_run import SortSession

T = TypeVar("T")
UNSET: Any = object()

NEED_CELL = "give an image, or --config CELL.toml to {what} with the cell"


@dataclass
class FileRig:
    """A rig of files (see the module doc). Each path is the flag's; None where the command
    has none. `sort_config`/`registration_config` left unset are the cell file's, resolved
    as the service resolves them at start."""

    config: Path | None = None
    system: Path | None = None
    camera: Path | None = None
    out: Path | None = None
    png: Path | None = None
    reference: Path | None = None  # the drift check's reference image (else the one kept)
    tone: ToneCurve | None = None  # None: the cell file camera's curve, else sRGB
    log: RunLog = NullLog
    sort_config: SortConfig | None = UNSET
    registration_config: RegistrationConfig | None = UNSET
    _cell: CellConfig | None = field(default=None, init=False, repr=False)
    _devices: Devices | None = field(default=None, init=False, repr=False)
    _held: tuple[Any, Any] | None = field(default=None, init=False, repr=False)
    _source: CalibrationSource | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        self._cell = load_cell_config(self.config) if self.config is not None else None
        if self.sort_config is UNSET or self.registration_config is UNSET:
            sort_config, registration_config = self._resolved_sections()
            if self.sort_config is UNSET:
                self.sort_config = sort_config
            if self.registration_config is UNSET:
                self.registration_config = registration_config

    def _resolved_sections(self) -> tuple[SortConfig | None, RegistrationConfig | None]:
        cell = self._cell
        if cell is None:
            return None, None
        if cell.sorting is None:
            return None, cell.registration
        from omnisort_hw.pipeline.sort import resolve_sorting

        scene = self._opened().scene if cell.sorting.from_scene else None
        return resolve_sorting(cell.sorting, cell.registration, scene)

    def _opened(self) -> Devices:
        """The cell file's devices, unconnected, opened once (a simulated cell is one world)."""
        if self._devices is None:
            from omnisort_hw.cell.devices import open_devices

            self._devices = open_devices(self._need_cell("use the devices").devices)
        return self._devices

    # -- files -----------------------------------------------------------------------------

    @property
    def runlog(self) -> RunLog:
        return self.log

    @property
    def system_path(self) -> Path:
        if self.system is None:
            raise InputError("--system: the system.json to use is needed")
        return self.system

    def system_record(self) -> tuple[dict[str, Any], str]:
        """--system's payload (a store file's checksum verified) and its path."""
        from omnisort_hw.pipeline.calibration_source import read_system_payload

        payload, _ = read_system_payload(self.system_path)
        return payload, str(self.system_path)

    def system_calibration(self) -> SystemCalibration:
        payload, where = self.system_record()
        return SystemCalibration.from_json(payload, source=where)

    def drift_reference(self, key: str) -> np.ndarray | None:
        """`--reference`, else the reference kept beside system.json for this calibration."""
        from omnisort_hw.pipeline.drift_check import load_reference

        if self.reference is not None:
            return read_image(self.reference)
        return load_reference(self.system_path.parent, key)

    @property
    def watchdog_config(self) -> WatchdogConfig:
        return self._cell.watchdog if self._cell is not None else WatchdogConfig()

    def camera_model(self) -> OcamModel:
        from omnisort_hw.core.camera_io import load_camera_json

        if self.camera is None:
            raise InputError("--camera: the camera.json (intrinsics) to use is needed")
        model, _ = load_camera_json(self.camera)
        return model

    def tone_curve(self) -> ToneCurve:
        """The curve given, else the cell file camera's (as the service reads its camera's),
        else sRGB, what 8-bit image files hold."""
        if self.tone is not None:
            return self.tone
        camera = self._opened().camera if self._cell is not None else None
        return ToneCurve.parse(camera.tone_curve) if camera is not None else SRGB

    def laser_color(self) -> str:
        """The cell file's `[laser] color`; red without a cell file."""
        return self._cell.devices.laser_color if self._cell is not None else "red"

    def target_defaults(self) -> tuple[str | None, float | None, str]:
        if self._cell is None:
            return None, None, "--separation"
        t = self._cell.target
        return t.kind, t.separation_mm, f"--separation (or [target] separation_mm in {self.config})"

    def _out(self) -> Path:
        if self.out is None:
            raise InputError("--out: the file to write is needed")
        return self.out

    def save_camera(self, model: OcamModel, record: Mapping[str, object]) -> Path:
        from omnisort_hw.core.camera_io import save_camera_json

        out = self._out()
        save_camera_json(out, model, **record)
        return out

    def save_system(self, payload: Mapping[str, object]) -> Path:
        return fileio.atomic_write_json(self._out(), dict(payload))

    def save_robot_base(self, record: Mapping[str, object], image: np.ndarray) -> Path:
        from omnisort_hw.pipeline.registration import write_robot_base

        return write_robot_base(self.system_path, record)

    def picture_path(self, kind: str, image: str | None) -> Path:
        """`--png`, else named after the image and the kind, beside system.json."""
        if self.png is not None:
            return self.png
        stem = Path(image).stem if image is not None else "capture"
        return self.system_path.with_name(f"{stem}_{kind}_overlay.png")

    def run_logged(
        self,
        fn: Callable[..., T],
        *args: Any,
        cancel: threading.Event | None = None,
        what: str = "job",
        **kwargs: Any,
    ) -> T:
        return fn(*args, log=self.log, **kwargs)

    # -- the cell file's devices -----------------------------------------------------------

    def _need_cell(self, what: str) -> CellConfig:
        if self._cell is None:
            raise InputError(NEED_CELL.format(what=what))
        return self._cell

    def has_laser(self) -> bool:
        return self._cell is not None and self._cell.devices.laser is not None

    @property
    def capture_dir(self) -> Path:
        """`captures/` beside the system.json the command writes or reads, as the service
        keeps its captures beside its own (the cell's state folder may not be the user's); the
        state folder's when the command uses the cell's store."""
        if self.out is None and self.system is None:  # a sort on the cell's own store
            return Path(self._need_cell("capture").storage.state_dir) / "captures"
        anchor = self.out if self.out is not None else self.system_path
        return anchor.parent / "captures"

    @property
    def capture_settings(self) -> CaptureSettings:
        return self._need_cell("measure").capture

    @contextmanager
    def measuring(self) -> Iterator[tuple[Any, Any]]:
        """The cell file's camera and laser: those a sort holds, else connected for this
        capture alone."""
        if self._held is not None:
            yield self._held
            return
        devices = self._opened()
        if devices.camera is None or devices.laser is None:
            raise InputError(f"{self.config}: a capture needs the [camera] and [laser] sections")
        with devices.camera as camera, devices.laser as laser:
            yield camera, laser

    def prune_captures(self) -> None:
        """The service prunes its capture folder; a command leaves it as it is."""

    def grab_frame(self, laser: bool) -> np.ndarray:
        """One frame of the cell file's camera with its laser at `laser` (off after)."""
        devices = self._opened()
        if devices.camera is None:
            raise InputError(f"{self.config}: a capture needs the [camera] section")
        with devices.camera as cam:
            if devices.laser is None:
                return np.asarray(cam.grab().image)
            with devices.laser as switch:
                switch.set(laser)
                try:
                    return np.asarray(cam.grab().image)
                finally:
                    if laser:
                        switch.set(False)

    # -- sorting (a `pipeline.sort_run.SortRig`) -------------------------------------------

    def _state_dir(self) -> Path:
        return Path(self._need_cell("sort").storage.state_dir)

    def calibration_source(self) -> CalibrationSource:
        """`--system` (checked for age as the store checks), else the cell's store."""
        from omnisort_hw.pipeline.calibration_source import FileCalibration, StoreCalibration

        storage = self._need_cell("sort").storage
        if self.system is not None:
            self._source = FileCalibration(self.system, storage.max_age_days or None)
        else:
            self._source = StoreCalibration(self._store())
        return self._source

    def _store(self) -> CalibrationStore:
        """The cell's store, expecting the camera attached now, as the service's store does
        once its camera is connected (the camera is opened for its serial; nothing moves)."""
        from omnisort_hw.pipeline.calibration_store import CalibrationStore

        store = CalibrationStore.from_config(self._need_cell("sort").storage)
        camera = self._opened().camera
        if store.expected_serial is None and camera is not None:
            with camera as cam:
                store.expected_serial = cam.serial
        return store

    def check_drift(self) -> None:
        """The service's gate: with the cell's store, its drift watchdog's check before a sort
        (a fresh frame against the reference, when `[watchdog] before_sort`) and its record;
        with `--system`, the record of a drift of that calibration in the cell's drift state.
        CalibrationDriftError when a drift is unacknowledged."""
        from omnisort_hw.cell.watchdog import DriftWatchdog, WatchdogPorts
        from omnisort_hw.errors import CalibrationDriftError
        from omnisort_hw.pipeline.calibration_source import read_system_payload
        from omnisort_hw.pipeline.drift_check import (
            calibration_key,
            drift_refusal,
            load_drift_state,
        )

        cell = self._need_cell("sort")
        if self.system is None:
            ports = WatchdogPorts(
                self._store(),
                lambda: self.grab_frame(laser=False),
                lambda: self.registration_config,
                lambda: self.log,
            )
            DriftWatchdog(ports, cell.watchdog).before_sort()
            return
        payload, _ = read_system_payload(self.system)
        why = drift_refusal(load_drift_state(self._state_dir()), calibration_key(payload))
        if why is not None:
            raise CalibrationDriftError(why)

    @contextmanager
    def sorting(self, request: SortRequest) -> Iterator[SortSession]:
        """As the service holds its cell: the cell's instance lock (refused while its service
        runs), the job journal (the sort and the cube in flight, so a cube held after a crash
        is placed first), the devices connected for the run, the simulated cell's truth as
        verifier where there is one."""
        from omnisort_hw.cell.journal import JobJournal
        from omnisort_hw.cell.lock import InstanceLock
        from omnisort_hw.fileio import check_writable
        from omnisort_hw.pipeline.sort_capture import sort_capture_for
        from omnisort_hw.pipeline.sort_run import SortSession

        devices = self._opened()
        camera, laser, arm = devices.camera, devices.laser, devices.arm
        if camera is None or arm is None:
            raise ConfigError(f"{self.config}: [camera] and [arm] sections are needed to sort")
        state_dir = self._state_dir()
        check_writable(state_dir, "[storage] state_dir")
        args = {"max_objects": request.max_objects, "colors": request.colors}
        with InstanceLock(state_dir), ExitStack() as stack:
            journal = JobJournal(state_dir)
            journal.recover()
            journal.start("sort", "cli", args)
            try:
                for dev in (camera, laser, arm):
                    if dev is not None:
                        stack.enter_context(dev)
                verifier = devices.scene.verifier() if devices.scene is not None else None
                if verifier is not None:
                    verifier.start()
                    stack.callback(verifier.stop)
                self._held = (camera, laser)
                stack.callback(self._release)
                off = (lambda: laser.set(False)) if laser is not None else None
                yield SortSession(
                    camera,
                    laser,
                    arm,
                    journal,
                    acquire=sort_capture_for(self, off),
                    verifier=verifier,
                )
            except BaseException as exc:
                journal.finish("failed", f"{getattr(exc, 'code', type(exc).__name__)}: {exc}")
                raise
            journal.finish("done", "sort done")

    def _release(self) -> None:
        self._held = None
