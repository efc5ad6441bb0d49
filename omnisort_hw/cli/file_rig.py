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
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from omnisort_hw import fileio
from omnisort_hw.config.capture import CaptureSettings
from omnisort_hw.config.cell import CellConfig, load_cell_config
from omnisort_hw.config.sorting import RegistrationConfig
from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.core.radiometry import SRGB, ToneCurve
from omnisort_hw.errors import InputError
from omnisort_hw.pipeline.image_files import read_image
from omnisort_hw.runlog import NullLog, RunLog

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
    map_png: Path | None = None
    tone: ToneCurve = SRGB
    log: RunLog = NullLog
    sort_config: SortConfig | None = UNSET
    registration_config: RegistrationConfig | None = UNSET
    _cell: CellConfig | None = field(default=None, init=False, repr=False)

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
        from omnisort_hw.cell.devices import open_devices
        from omnisort_hw.pipeline.sort import resolve_sorting

        scene = open_devices(cell.devices).scene if cell.sorting.from_scene else None
        return resolve_sorting(cell.sorting, cell.registration, scene)

    # -- files -----------------------------------------------------------------------------

    @property
    def runlog(self) -> RunLog:
        return self.log

    @property
    def system_path(self) -> Path:
        if self.system is None:
            raise InputError("--system: the system.json to use is needed")
        return self.system

    def system_calibration(self) -> SystemCalibration:
        from omnisort_hw.pipeline.calibration_source import read_system_payload

        payload, _ = read_system_payload(self.system_path)
        return SystemCalibration.from_json(payload, source=str(self.system_path))

    def camera_model(self) -> OcamModel:
        from omnisort_hw.core.camera_io import load_camera_json

        if self.camera is None:
            raise InputError("--camera: the camera.json (intrinsics) to use is needed")
        model, _ = load_camera_json(self.camera)
        return model

    def tone_curve(self) -> ToneCurve:
        return self.tone

    def target_defaults(self) -> tuple[str | None, float | None, str]:
        if self._cell is None:
            return None, None, "--separation"
        t = self._cell.target
        return t.kind, t.separation_mm, f"--separation (or [target] separation_mm in {self.config})"

    def _out(self) -> Path:
        if self.out is None:
            raise InputError("--out: the file to write is needed")
        return self.out

    def save_camera(self, model: OcamModel, record: Mapping[str, Any]) -> Path:
        from omnisort_hw.core.camera_io import save_camera_json

        out = self._out()
        save_camera_json(out, model, **record)
        return out

    def save_system(self, payload: Mapping[str, Any]) -> Path:
        return fileio.atomic_write_json(self._out(), dict(payload))

    def save_robot_base(self, record: Mapping[str, Any], image: np.ndarray) -> Path:
        from omnisort_hw.pipeline.registration import write_robot_base

        return write_robot_base(self.system_path, record)

    def map_picture_path(self, image: str | None) -> Path:
        """`--png`, else named after the image, beside system.json."""
        if self.map_png is not None:
            return self.map_png
        stem = Path(image).stem if image is not None else "capture"
        return self.system_path.with_name(f"{stem}_map_overlay.png")

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
        keeps its captures beside its own (the cell's state folder may not be the user's)."""
        anchor = self.out if self.out is not None else self.system_path
        return anchor.parent / "captures"

    @property
    def capture_settings(self) -> CaptureSettings:
        return self._need_cell("measure").capture

    @contextmanager
    def measuring(self) -> Iterator[tuple[Any, Any]]:
        """The cell file's camera and laser, connected for this capture alone."""
        from omnisort_hw.cell.devices import open_devices

        devices = open_devices(self._need_cell("measure").devices)
        if devices.camera is None or devices.laser is None:
            raise InputError(f"{self.config}: a capture needs the [camera] and [laser] sections")
        with devices.camera as camera, devices.laser as laser:
            yield camera, laser

    def prune_captures(self) -> None:
        """The service prunes its capture folder; a command leaves it as it is."""

    def frame(self, image: str | None, laser: bool) -> np.ndarray:
        """The file `image`, or one frame of the cell file's camera with its laser at `laser`
        (off after)."""
        from omnisort_hw.cell.devices import open_devices

        if image is not None:
            return read_image(image)
        devices = open_devices(self._need_cell("capture").devices)
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
