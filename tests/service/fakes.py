"""In-memory devices implementing the `drivers.base` contracts, for service tests.

They are test doubles for the protocol and concurrency tests only (no geometry): the arm moves
linearly in joint space over `move_seconds`, `stop()` ends a motion at once, and every
command is appended to `journal` (and to `journal_path` when given) so a test in another
process can check what the service did on shutdown.
"""

from __future__ import annotations

import functools
import json
import threading
import time
from pathlib import Path

import numpy as np

from drivers.base import (
    Arm,
    Camera,
    Frame,
    Gripper,
    LaserSwitch,
    MotionLimits,
    SafetyStatus,
    as_pose_matrix,
)
from drivers.errors import DeviceTimeoutError
from omnisort_hw.cell.cell import Cell, CellDevices
from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.pipeline.calibration_store import REQUIRED_KEYS, CalibrationStore


class Journal:
    def __init__(self, path: Path | None = None) -> None:
        self.path = path
        self.events: list[str] = []
        self._lock = threading.Lock()

    def add(self, event: str) -> None:
        with self._lock:
            self.events.append(event)
            if self.path is not None:
                with open(self.path, "a", encoding="utf-8") as fh:
                    fh.write(event + "\n")


class FakeCamera(Camera):
    def __init__(self, journal: Journal, serial: str = "FAKE-CAM-1", fail: bool = False) -> None:
        self.journal = journal
        self._serial = serial
        self._connected = False
        self._seq = 0
        self.fail = fail

    @property
    def name(self) -> str:
        return "fake-camera"

    @property
    def is_connected(self) -> bool:
        return self._connected

    def connect(self) -> None:
        self._connected = True

    def close(self) -> None:
        self._connected = False
        self.journal.add("camera close")

    def grab(self, timeout_s: float | None = None) -> Frame:
        if self.fail:
            raise DeviceTimeoutError("fake camera: no frame", device=self.name)
        self._seq += 1
        img = np.zeros((48, 64, 3), np.uint8)
        img[:, :, 2] = self._seq % 255
        return Frame.now(img, self._seq)

    @property
    def resolution(self) -> tuple[int, int]:
        return (64, 48)

    @property
    def serial(self) -> str:
        return self._serial


class FakeLaser(LaserSwitch):
    def __init__(self, journal: Journal) -> None:
        self.journal = journal
        self._on = False
        self._connected = False

    @property
    def name(self) -> str:
        return "fake-laser"

    @property
    def is_connected(self) -> bool:
        return self._connected

    def connect(self) -> None:
        self._connected = True

    def close(self) -> None:
        self._connected = False
        self.journal.add("laser close")

    def set(self, on: bool, timeout_s: float | None = None) -> None:
        self._on = bool(on)
        self.journal.add(f"laser {'on' if on else 'off'}")

    def state(self, timeout_s: float | None = None) -> bool:
        return self._on


class FakeGripper(Gripper):
    def __init__(self) -> None:
        self._closed = False

    def open(self, timeout_s: float = 3.0) -> None:
        self._closed = False

    def close(self, timeout_s: float = 3.0) -> None:
        self._closed = True

    @property
    def is_closed(self) -> bool:
        return self._closed

    @property
    def holding(self) -> bool | None:
        return None


class FakeArm(Arm):
    def __init__(self, journal: Journal, move_seconds: float = 0.5) -> None:
        self.journal = journal
        self.move_seconds = move_seconds
        self._q = np.zeros(6)
        self._T = np.eye(4)
        self._T[:3, 3] = [400.0, 0.0, 300.0]
        self._connected = False
        self._stop = threading.Event()
        self._gripper = FakeGripper()
        self.protective_stop = False
        self.moving = threading.Event()

    @property
    def name(self) -> str:
        return "fake-arm"

    @property
    def is_connected(self) -> bool:
        return self._connected

    def connect(self) -> None:
        self._connected = True

    def close(self) -> None:
        self._connected = False
        self.journal.add("arm close")

    @property
    def limits(self) -> MotionLimits:
        return MotionLimits()

    @property
    def gripper(self) -> Gripper:
        return self._gripper

    def joint_positions(self) -> np.ndarray:
        return self._q.copy()

    def tcp_pose(self) -> np.ndarray:
        return self._T.copy()

    def _run(self, what: str) -> bool:
        self._stop.clear()
        self.moving.set()
        self.journal.add(f"arm {what} start")
        try:
            end = time.monotonic() + self.move_seconds
            while time.monotonic() < end:
                if self._stop.wait(0.01):
                    self.journal.add(f"arm {what} interrupted")
                    return False
            return True
        finally:
            self.moving.clear()

    def move_joints(self, q_deg, speed_deg_s=None, accel_deg_s2=None, timeout_s=60.0) -> None:
        q = self.limits.check_joints(q_deg)
        self.safety_status().raise_if_stopped(self.name)
        if self._run("move_joints"):
            self._q = q

    def move_linear(self, pose, speed_mm_s=None, accel_mm_s2=None, timeout_s=60.0) -> None:
        T = self.limits.check_pose(as_pose_matrix(pose))
        self.safety_status().raise_if_stopped(self.name)
        if self._run("move_linear"):
            self._T = T

    def stop(self) -> None:
        self._stop.set()
        self.journal.add("arm stop")

    def safety_status(self) -> SafetyStatus:
        return SafetyStatus(self.protective_stop, False, "RUNNING")


@functools.cache
def _model_dict() -> str:
    """The stand-in camera model, fitted once per test process (the fit takes a while)."""
    return json.dumps(OcamModel.equidistant(640, 480).to_dict())


def camera_payload() -> dict:
    return {**json.loads(_model_dict()), "rms_px": 0.1}


def system_payload() -> dict:
    payload: dict = {k: {} for k in REQUIRED_KEYS["system"]}
    payload["camera"] = camera_payload()
    payload["created"] = "2026-01-01T00:00:00+00:00"
    payload["robot_base"] = {"matrix": np.eye(4).tolist(), "xyz_mm": [0.0, 0.0, 0.0]}
    return payload


def write_calibration(store: CalibrationStore, serial: str = "FAKE-CAM-1") -> None:
    store.save_camera(camera_payload(), camera_serial=serial)
    store.save_system(system_payload(), camera_serial=serial)


def make_cell(
    state_dir: Path,
    log_dir: Path | None = None,
    move_seconds: float = 0.5,
    calibrated: bool = True,
    journal_path: Path | None = None,
    max_file_bytes: int | None = None,
) -> tuple[Cell, CellDevices, Journal]:
    from omnisort_hw.cell.rrd import RunLogRotator

    journal = Journal(journal_path)
    devices = CellDevices(FakeCamera(journal), FakeLaser(journal), FakeArm(journal, move_seconds))
    store = CalibrationStore(state_dir)
    if calibrated:
        write_calibration(store)
    rotator = (
        RunLogRotator(log_dir, keep=5, max_file_bytes=max_file_bytes)
        if log_dir is not None
        else None
    )
    cell = Cell(devices, store, rotator)
    cell.connect()
    return cell, devices, journal
