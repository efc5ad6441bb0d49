"""Where a use case gets the system calibration, and the gate every motion passes.

`check_motion_allowed` refuses motion (MotionRefusedError) unless the calibration is present,
intact, recent enough and has the robot registered: the service's store, a system.json file
(plain or written by the store), or one held in memory (evaluation, tests).
"""

from __future__ import annotations

from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.errors import CalibrationFileError, MotionRefusedError, NotRegisteredError
from omnisort_hw.fileio import read_calibration_json


class CalibrationSource:
    """Where the pipeline gets the system calibration, and the gate every motion passes."""

    def check_motion_allowed(self) -> None:
        raise NotImplementedError

    def system(self) -> SystemCalibration:
        raise NotImplementedError


class StoreCalibration(CalibrationSource):
    """The service's calibration store (checksums, age, camera serial)."""

    def __init__(self, store: Any) -> None:
        self.store = store

    def check_motion_allowed(self) -> None:
        self.store.check_motion_allowed()

    def system(self) -> SystemCalibration:
        rec = self.store.read("system")
        return SystemCalibration.from_json(rec.payload, source=str(rec.path))


def read_system_payload(path: str | Path) -> tuple[dict[str, Any], str | None]:
    """A system.json's payload and, for one written by the store, its save time, the store's
    checksum verified (a tampered file is refused); a plain file (the CLI's) as it is."""
    path = Path(path)
    raw = read_calibration_json(path, "system")
    if "checksum" not in raw:
        return raw, None
    from omnisort_hw.pipeline.calibration_store import read_calibration_file

    rec = read_calibration_file(path, "system")
    return dict(rec.payload), rec.saved.isoformat()


class FileCalibration(CalibrationSource):
    """A system.json file (plain, or written by the store: then its checksum is verified); it
    must parse and be no older than `max_age_days` (from its save or creation time)."""

    def __init__(self, path: str | Path, max_age_days: float | None = None) -> None:
        self.path = Path(path)
        self.max_age_days = max_age_days

    def _payload(self) -> dict[str, Any]:
        payload, saved = read_system_payload(self.path)
        return {**payload, "_saved": saved} if saved else payload

    def check_motion_allowed(self) -> None:
        try:
            payload = self._payload()
            SystemCalibration.from_json(payload, source=str(self.path))
        except CalibrationFileError as exc:
            raise MotionRefusedError(f"motion refused: calibration not usable: {exc}") from None
        if self.max_age_days is None:
            return
        stamp = payload.get("_saved") or payload.get("created")
        try:
            when = datetime.fromisoformat(str(stamp))
        except ValueError:
            raise MotionRefusedError(
                f"motion refused: {self.path}: no valid creation time ('created'), so its age "
                "cannot be checked"
            ) from None
        if when.tzinfo is None:
            when = when.replace(tzinfo=UTC)
        age = (datetime.now(UTC) - when).total_seconds() / 86400.0
        if age > self.max_age_days:
            raise MotionRefusedError(
                f"motion refused: {self.path} is {age:.1f} days old, older than "
                f"{self.max_age_days:g} days; recalibrate"
            )

    def system(self) -> SystemCalibration:
        payload = self._payload()
        payload.pop("_saved", None)
        return SystemCalibration.from_json(payload, source=str(self.path))


class MemoryCalibration(CalibrationSource):
    """A calibration held in memory (evaluation and tests); always usable."""

    def __init__(self, calib: SystemCalibration) -> None:
        self.calib = calib

    def check_motion_allowed(self) -> None:
        return None

    def system(self) -> SystemCalibration:
        return self.calib


def robot_base_T(
    calib: SystemCalibration, source: str = "system.json", for_motion: bool = True
) -> np.ndarray:
    """T_SB from the calibration's `robot_base`. Without one: MotionRefusedError before a
    motion, NotRegisteredError otherwise (locating cubes moves nothing)."""
    rb = calib.robot_base
    error = MotionRefusedError if for_motion else NotRegisteredError
    prefix = "motion refused: " if for_motion else ""
    if not isinstance(rb, Mapping) or "matrix" not in rb:
        raise error(
            f"{prefix}{source} has no robot_base: register the robot first "
            "(omnisort register-robot, or the register_robot command)"
        )
    T = np.asarray(rb["matrix"], float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise error(f"{prefix}{source}: robot_base.matrix is not a 4x4 pose")
    return T
