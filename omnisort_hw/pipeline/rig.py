"""The one interface every use case runs on: what it needs of a cell, and nothing more.

Two implementations: the service's `cell.Cell` (its devices held under their locks, its
calibration store, compute worker and run log) and the CLI's `cli.file_rig.FileRig`
(explicit files, and the cell file's devices opened for one capture). A use case is
`pipeline.<use case>.run(rig, request)`, so a capture gives the same answer through either door.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Protocol, TypeVar

import numpy as np

from omnisort_hw.config.sorting import RegistrationConfig
from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.core.radiometry import ToneCurve
from omnisort_hw.errors import MotionRefusedError
from omnisort_hw.pipeline.cell_acquisition import CaptureRig

T = TypeVar("T")


class Rig(CaptureRig, Protocol):
    """A cell as the use cases see it (see the module doc)."""

    @property
    def sort_config(self) -> SortConfig | None: ...

    @property
    def registration_config(self) -> RegistrationConfig | None: ...

    @property
    def system_path(self) -> Path:
        """The system.json the rig reads and writes (named in messages)."""
        ...

    def system_calibration(self) -> SystemCalibration:
        """The camera-laser calibration to work with, verified (checksum, camera)."""
        ...

    def camera_model(self) -> OcamModel:
        """The intrinsics to calibrate the extrinsics with."""
        ...

    def tone_curve(self) -> ToneCurve:
        """The camera's transfer curve, undone where edges are located."""
        ...

    def laser_color(self) -> str:
        """The laser's colour (`[laser] color`: red, green or blue), what its stripe is."""
        ...

    def target_defaults(self) -> tuple[str | None, float | None, str]:
        """(target kind, measured wall distance mm, the field that gives it) of the cell file's
        `[target]`, for a calibration request that leaves them out."""
        ...

    def has_laser(self) -> bool: ...

    def grab_frame(self, laser: bool) -> np.ndarray:
        """One frame of the cell's camera with its laser switched to `laser` (off after);
        `cell_acquisition.frame` gives a request's image or this."""
        ...

    def run_logged(
        self,
        fn: Callable[..., T],
        *args: Any,
        cancel: threading.Event | None = None,
        what: str = "job",
        **kwargs: Any,
    ) -> T:
        """`fn(*args, log=..., **kwargs)`, CPU-bound work, logged to the rig's run log."""
        ...

    def save_camera(self, model: OcamModel, record: Mapping[str, object]) -> Path:
        """Write a new camera.json of `model` with its calibration `record`; its path."""
        ...

    def save_system(self, payload: Mapping[str, object]) -> Path:
        """Write a new system.json; its path."""
        ...

    def save_robot_base(self, record: Mapping[str, object], image: np.ndarray) -> Path:
        """Put a registration into system.json (and keep `image` as the drift reference where
        the rig watches drift); the file's path."""
        ...

    def picture_path(self, kind: str, image: str | None) -> Path:
        """Where the picture of a `kind` ("map", "registration", "locate") of `image` (None: a
        capture) goes."""
        ...


def raise_if_cancelled(cancel: threading.Event | None, what: str = "move") -> None:
    """MotionRefusedError when the job was cancelled (checked between a use case's steps)."""
    if cancel is not None and cancel.is_set():
        raise MotionRefusedError(f"{what} cancelled")
