"""The cell: the configured devices wired to calibration storage, the run log and the core.

The service calls one `Cell` from several threads: the job thread (one long command at a
time), the quick-command pool (status, capture, laser) and the safety pool (stop, estop).
Access to the camera and the laser switch is serialised with a lock each; `Arm.stop()` may
always be called concurrently with a motion (the driver contract says it always passes).
Status reads use short-lived caches so that many clients polling `status` never queue behind
a device.

Pipeline commands (calibrate, map, register_robot, locate, sort) call the use-case layer
(`omnisort_hw.pipeline`) with the cell's devices, calibration store, run log and the cell
file's typed record (`config.cell.CellConfig`, loaded once at start); a command whose section
is missing raises `NotAvailableError` naming it.
"""

from __future__ import annotations

import base64
import logging
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from omnisort_hw import fileio
from omnisort_hw.cell.compute_worker import ComputeWorker
from omnisort_hw.cell.device_locks import (
    VIEW_GRAB_TIMEOUT_S,
    CameraLock,
    locked,
)
from omnisort_hw.cell.devices import Devices, open_devices
from omnisort_hw.cell.jobs import CellJobs
from omnisort_hw.cell.journal import JobJournal
from omnisort_hw.cell.status import Cached, Caches, arm_summary, camera_summary, error_text
from omnisort_hw.cell.status_reply import CellStatus
from omnisort_hw.cell.watchdog import DriftWatchdog, WatchdogPorts
from omnisort_hw.config.capture import CaptureSettings
from omnisort_hw.config.cell import CellConfig
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.errors import InputError, NotAvailableError, OmnisortError
from omnisort_hw.pipeline.arm_motion import ArmMover
from omnisort_hw.pipeline.calibration_store import CalibrationStore
from omnisort_hw.pipeline.gripper_load import assess
from omnisort_hw.pipeline.replies import (
    ArmSafety,
    CaptureReply,
    DetectReply,
    ImageReply,
    LaserReply,
    MoveReply,
    PictureFileReply,
    ViewReply,
)
from omnisort_hw.pipeline.requests import DetectRequest, MoveRequest
from omnisort_hw.pipeline.sort import resolve_sorting
from omnisort_hw.runlog import RunLog

if TYPE_CHECKING:
    from omnisort_hw.cell.rrd import RunLogRotator

log = logging.getLogger(__name__)

STATUS_CACHE_S = 0.05
STATUS_POLL_S = 0.1
CALIBRATION_CACHE_S = 1.0
LASER_CACHE_S = 1.0
# The devices of one cell (a missing device is None): the device factory's record.
CellDevices = Devices


def _encoded(image: Any, fmt: str, params: Sequence[int] = ()) -> bytes:
    """`image` as a png or jpg file's bytes."""
    import cv2

    ok, buf = cv2.imencode(f".{fmt}", image, list(params))
    if not ok:
        raise OmnisortError(f"could not encode the image as {fmt}")
    return bytes(buf.tobytes())


def _jpeg(image: Any, width: int, quality: int) -> ImageReply:
    """`image` scaled to at most `width` px (never enlarged) as a JPEG in base64, with its
    size and `scale` (its px per px of `image`: overlays in `image` px times this)."""
    import cv2

    h, w = image.shape[:2]
    scale = min(1.0, width / w)
    if scale < 1.0:
        size = (max(1, round(w * scale)), max(1, round(h * scale)))
        image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    data = _encoded(image, "jpg", (cv2.IMWRITE_JPEG_QUALITY, int(quality)))
    return ImageReply(
        width=int(image.shape[1]),
        height=int(image.shape[0]),
        scale=scale,
        format="jpg",
        base64=base64.b64encode(data).decode("ascii"),
    )


def _iso(wall: float) -> str:
    return datetime.fromtimestamp(wall, UTC).isoformat(timespec="milliseconds")


class Cell:
    """Devices + calibration store + run log, for one robot cell; its use cases are `jobs`."""

    def __init__(
        self,
        devices: CellDevices,
        store: CalibrationStore,
        runlog: RunLogRotator | RunLog | None = None,
        capture_dir: Path | None = None,
        capture_keep: int = 50,
        config: CellConfig | None = None,
    ) -> None:
        self.devices = devices
        self.store = store
        self._runlog = runlog if runlog is not None else RunLog(None)
        self.capture_dir = capture_dir or Path(store.state_dir) / "captures"
        self.capture_keep = capture_keep
        self.config = config or CellConfig()
        # [sorting] and [registration] resolved once (with the backend's scene for
        # from_scene): a bad combination stops the service at start, not at the first sort.
        self.sort_config: SortConfig | None = None
        self.registration_config = self.config.registration
        if self.config.sorting is not None:
            self.sort_config, self.registration_config = resolve_sorting(
                self.config.sorting, self.config.registration, devices.scene
            )
        self._camera_lock = CameraLock()
        self._laser_lock = threading.Lock()
        self._cache_lock = threading.Lock()
        self._caches = Caches()
        self._connected = False
        self._mover = ArmMover()
        self._snapshot: CellStatus | None = None
        self._snapshot_at = 0.0
        self._poller_stop = threading.Event()
        self._poller: threading.Thread | None = None
        # Called (under the device's lock) before anything is switched on; raises to refuse.
        # The service sets it to its state rules (nothing actuates in `fault`).
        self.actuation_guard: Callable[[], None] | None = None
        self.journal = JobJournal(store.state_dir)
        self.compute = ComputeWorker()  # CPU-bound jobs run here, not in the service's process
        self.jobs = CellJobs(self)
        self.drift = DriftWatchdog(
            WatchdogPorts(
                store,
                self.jobs.dark_frame,
                lambda: self.registration_config,
                lambda: self.runlog,
            ),
            self.config.watchdog,
        )

    # -- construction and life cycle -------------------------------------------------------

    @classmethod
    def from_settings(cls, settings: CellConfig, devices_in_child: bool = False) -> Cell:
        """Build the cell of a configuration: devices from the device factory (`in_child`: the
        service's choice), store, run log."""
        from omnisort_hw.cell.rrd import RunLogRotator

        devices = open_devices(settings.devices, in_child=devices_in_child)
        lg = settings.logging
        rotator = RunLogRotator(
            lg.log_dir if lg.rerun else None,
            keep=lg.rrd_keep,
            max_total_bytes=int(lg.rrd_max_total_mb * 1e6),
            max_file_bytes=int(lg.rrd_max_file_mb * 1e6),
        )
        store = CalibrationStore.from_config(settings.storage)
        return cls(
            devices,
            store,
            rotator,
            capture_keep=settings.service.capture_keep,
            config=settings,
        )

    @property
    def runlog(self) -> RunLog:
        """The RunLog to write to now (the rotator may have started a new file)."""
        rl = self._runlog
        return rl if isinstance(rl, RunLog) else rl.log

    @property
    def runlog_path(self) -> Path | None:
        return self.runlog.path

    def roll_runlog(self) -> bool:
        """Start a new `.rrd` file when the current one is over its size limit or its file or
        folder went away; never raises (a failure turns the run log off, see `log_health`)."""
        rl = self._runlog
        return False if isinstance(rl, RunLog) else rl.check()

    def log_health(self) -> dict[str, Any]:
        """The run log's health for `status`: ok, the file, or the problem and since when."""
        rl = self._runlog
        if isinstance(rl, RunLog):
            return {"ok": True, "rrd": str(rl.path) if rl.path else None}
        return asdict(rl.health())

    def connect(self) -> None:
        """Connect every device (a DeviceError propagates) and check the camera serial."""
        for name, dev in self.devices.items():
            if dev is not None:
                log.info("connecting %s %s", name, dev.name)
                dev.connect()
        cam = self.devices.camera
        if cam is not None and self.store.expected_serial is None:
            self.store.expected_serial = cam.serial
        self.store.remove_stale_temps()
        self._connected = True
        self.refresh_status()
        self._poller_stop.clear()
        self._poller = threading.Thread(target=self._poll_status, name="status-poll", daemon=True)
        self._poller.start()
        self.drift.start()
        self.runlog.event("service/devices", f"connected: {self.device_names()}")

    def device_names(self) -> dict[str, str | None]:
        return {name: (dev.name if dev is not None else None) for name, dev in self.devices.items()}

    def close(self) -> list[str]:
        """Safe shutdown: arm stopped, laser off, devices closed, run log flushed; never raises.

        Returns the problems met (also logged), so the caller can report them.
        """
        self._poller_stop.set()
        self.drift.stop()
        if self._poller is not None:
            self._poller.join(timeout=2.0)
            self._poller = None
        with self._cache_lock:
            self._snapshot = None
        problems = self.make_safe()
        for name, dev in self.devices.items():
            if dev is None:
                continue
            try:
                dev.close()
            except Exception as exc:
                problems.append(f"{name} close: {exc}")
        for p in problems:
            log.warning("shutdown: %s", p)
        self.runlog.event("service/devices", "closed", level="INFO")
        rl = self._runlog
        rl.close()
        self.compute.close()
        self._connected = False
        return problems

    def make_safe(self) -> list[str]:
        """Stop the arm and switch the laser off, trying both whatever fails; returns problems."""
        problems: list[str] = []
        arm = self.devices.arm
        if arm is not None and arm.is_connected:
            try:
                arm.stop()
            except Exception as exc:
                problems.append(f"arm stop: {exc}")
        laser = self.devices.laser
        if laser is not None and laser.is_connected:
            # The laser lock may be held by a command stuck on the device: switch off anyway.
            got = self._laser_lock.acquire(timeout=1.0)
            try:
                laser.off()
                self._cache_laser(False)
            except Exception as exc:
                problems.append(f"laser off: {exc}")
            finally:
                if got:
                    self._laser_lock.release()
        return problems

    # -- helpers ---------------------------------------------------------------------------

    def _need(self, name: str) -> Any:
        dev = getattr(self.devices, name)
        if dev is None:
            raise NotAvailableError(f"no {name} in this cell's configuration ([{name}] section)")
        return dev

    @contextmanager
    def measuring(self) -> Iterator[tuple[Any, Any]]:
        """(camera, laser) held for one measurement capture (`pipeline.cell_acquisition`):
        refused when nothing may actuate; the laser's state is read back at the end."""
        camera, laser = self._need("camera"), self._need("laser")
        if self.actuation_guard is not None:
            self.actuation_guard()
        with self._camera_lock.held(), locked(self._laser_lock, "laser"):
            try:
                yield camera, laser
            finally:
                self._cache_laser(bool(laser.state()))

    @property
    def capture_settings(self) -> CaptureSettings:
        return self.config.capture

    def _cache_laser(self, on: bool) -> None:
        with self._cache_lock:
            self._caches.laser = Cached(bool(on), time.monotonic())

    # -- status ----------------------------------------------------------------------------

    def calibration_status(self) -> dict[str, Any]:
        """`CalibrationStore.status()`, recomputed when a file changes or after one second."""
        key: list[tuple[int, int, int] | None] = []
        for kind in ("camera", "system"):
            try:
                st = self.store.path(kind).stat()
                key.append((st.st_ino, st.st_mtime_ns, st.st_size))
            except OSError:
                key.append(None)
        with self._cache_lock:
            c = self._caches
            if c.calibration_key == key and c.calibration.fresh(CALIBRATION_CACHE_S):
                return dict(c.calibration.value)
        value = self.store.status()
        with self._cache_lock:
            self._caches.calibration = Cached(value, time.monotonic())
            self._caches.calibration_key = key
        return dict(value)

    def _arm_status(self) -> dict[str, Any]:
        arm = self.devices.arm
        if arm is None:
            return {"configured": False}
        with self._cache_lock:
            if self._caches.arm.fresh(STATUS_CACHE_S):
                return dict(self._caches.arm.value)
        out = arm_summary(arm)
        with self._cache_lock:
            self._caches.arm = Cached(out, time.monotonic())
        return out

    def _laser_status(self) -> dict[str, Any]:
        laser = self.devices.laser
        if laser is None:
            return {"configured": False}
        out: dict[str, Any] = {
            "configured": True,
            "name": laser.name,
            "connected": laser.is_connected,
        }
        with self._cache_lock:
            cached = self._caches.laser
            if cached.fresh(LASER_CACHE_S):
                out["on"] = cached.value
                return out
        if laser.is_connected and self._laser_lock.acquire(timeout=0.05):
            try:
                on = laser.state()
                self._cache_laser(on)
                out["on"] = on
            except Exception as exc:
                out.update(error_text(exc))
            finally:
                self._laser_lock.release()
        else:
            out["on"] = cached.value
            out["cached"] = True
        return out

    def _camera_status(self) -> dict[str, Any]:
        return camera_summary(self.devices.camera)

    def read_status(self) -> CellStatus:
        """Devices and calibration read now (device calls; the poller thread calls this)."""
        return {
            "devices": {
                "camera": self._camera_status(),
                "laser": self._laser_status(),
                "arm": self._arm_status(),
            },
            "calibration": self.calibration_status(),
            "rrd": str(self.runlog_path) if self.runlog_path else None,
            "logging": self.log_health(),
            "gripper": assess(self.devices.arm, self.journal.in_flight()).to_dict(),
            "drift": self.drift.status(),
        }

    def status(self) -> CellStatus:
        """The latest status snapshot, never waiting for a device: the poller thread refreshes
        it every STATUS_POLL_S; `status_age_s` says how old it is. Without a poller (not
        connected) it is read now."""
        with self._cache_lock:
            snap, at = self._snapshot, self._snapshot_at
        if snap is None:
            return self.read_status()
        out = snap.copy()
        out["status_age_s"] = round(time.monotonic() - at, 3)
        return out

    def _poll_status(self) -> None:
        while not self._poller_stop.wait(STATUS_POLL_S):
            try:
                snap = self.read_status()
            except Exception as exc:
                log.warning("status poll failed: %s", exc)
                continue
            with self._cache_lock:
                self._snapshot, self._snapshot_at = snap, time.monotonic()

    def refresh_status(self) -> None:
        """Read the status now into the snapshot (after a command changed something)."""
        snap = self.read_status()
        with self._cache_lock:
            self._snapshot, self._snapshot_at = snap, time.monotonic()

    # -- quick commands --------------------------------------------------------------------

    def grab(self, timeout_s: float | None = None) -> Any:
        """One fresh frame (`drivers.base.Frame`), logged as `camera/raw`."""
        cam = self._need("camera")
        with self._camera_lock.held():
            frame = cam.grab(timeout_s)
        rl = self.runlog
        rl.set_step("frame", int(frame.sequence))
        rl.image("camera/raw", frame.image)
        return frame

    def set_laser(self, on: bool) -> bool:
        """Switch the laser (confirmed by the driver's read-back) and return the state."""
        laser = self._need("laser")
        with locked(self._laser_lock, "laser"):
            if on and self.actuation_guard is not None:
                self.actuation_guard()
            laser.set(bool(on))
            state = bool(laser.state())
        self._cache_laser(state)
        self.runlog.event("laser/state", "on" if state else "off")
        return state

    def laser(self, on: bool | None = None) -> LaserReply:
        """Switch the laser when `on` is given; always read the state back."""
        laser = self._need("laser")
        if on is not None:
            return LaserReply(self.set_laser(on))
        with locked(self._laser_lock, "laser"):
            state = bool(laser.state())
        self._cache_laser(state)
        return LaserReply(state)

    def capture(
        self, encoding: str = "path", fmt: str = "png", laser: bool | None = None
    ) -> CaptureReply:
        """Grab one image; return it as a file under `capture_dir` or as base64."""
        if laser is not None:
            self.set_laser(laser)
        frame = self.grab()
        ext = ".png" if fmt == "png" else ".jpg"
        data = _encoded(frame.image, fmt)
        h, w = frame.image.shape[:2]
        result = CaptureReply(
            sequence=int(frame.sequence),
            wall_time=_iso(frame.wall_time),
            width=int(w),
            height=int(h),
            format=fmt,
            bytes=len(data),
        )
        if encoding == "base64":
            return replace(result, base64=base64.b64encode(data).decode("ascii"))
        stamp = datetime.fromtimestamp(frame.wall_time, UTC).strftime("%Y%m%dT%H%M%S.%fZ")
        path = self.capture_dir / f"capture-{stamp}-{int(frame.sequence):06d}{ext}"
        fileio.atomic_write_bytes(path, data, keep_history=False)
        self.prune_captures()
        return replace(result, path=str(path))

    def view(self, width: int = 960, quality: int = 80) -> ViewReply:
        """A live picture for a screen: one fresh frame scaled to at most `width` px and
        JPEG-encoded (base64). Not logged (a screen asks often); refused (`busy`) rather than
        waited for while a command holds or wants the camera (`live_frame`)."""
        frame = self.live_frame()
        picture = _jpeg(frame.image, width, quality)
        return ViewReply(
            **vars(picture), sequence=int(frame.sequence), wall_time=_iso(frame.wall_time)
        )

    def live_frame(self) -> Any:
        """A fresh frame for a screen, the laser as it is: refused (`busy`) at once while a
        command waits for the camera, and after VIEW_LOCK_TIMEOUT_S while one holds it (a live
        picture gives way: a screen asking every half second must never keep a sort from its
        camera)."""
        cam = self._need("camera")
        with self._camera_lock.for_screen():
            return cam.grab(VIEW_GRAB_TIMEOUT_S)

    def detect(self, request: DetectRequest) -> DetectReply:
        """A calibration pattern found in a live frame or the request's image, with a picture
        of that frame (`pipeline.detection`): for a screen where a target is being placed."""
        from omnisort_hw.pipeline import detection

        found = detection.run(self.jobs, request)
        return replace(found.reply(), picture=_jpeg(found.image, request.width, request.quality))

    def picture(self, path: str, width: int = 960, quality: int = 85) -> PictureFileReply:
        """A picture this service wrote (a PNG in the calibration store's folder, as a reply's
        `overlay_png`), scaled to at most `width` px and JPEG-encoded (base64); any other file
        is refused (`bad_input`), so a client reads nothing else of the PC through it."""
        import cv2

        folder = self.store.path("system").parent.resolve()
        p = Path(path).resolve()
        if p.parent != folder or p.suffix != ".png":
            raise InputError(f"{path}: not a picture of this service (a PNG in {folder})")
        image = cv2.imread(str(p), cv2.IMREAD_COLOR)
        if image is None:
            raise InputError(f"{path}: no such picture, or not readable as PNG")
        return PictureFileReply(**vars(_jpeg(image, width, quality)), path=str(p))

    def prune_captures(self) -> None:
        files = sorted(self.capture_dir.glob("capture-*"))
        for old in files[: max(0, len(files) - self.capture_keep)]:
            old.unlink(missing_ok=True)

    # -- motion ----------------------------------------------------------------------------

    def check_motion_allowed(self) -> None:
        """Raise MotionRefusedError unless camera.json and system.json are usable."""
        self.store.check_motion_allowed()
        self.drift.check_motion_allowed()

    def move(self, request: MoveRequest, cancel: threading.Event | None = None) -> MoveReply:
        """Move to a joint target (joint space) or a Cartesian target (straight TCP line).

        Refused before anything reaches the arm when the calibration is not usable or the arm
        reports a safety stop; the driver checks its joint limits and workspace box itself.
        """
        arm = self._need("arm")
        self.check_motion_allowed()
        return self._mover.move(arm, self.runlog, request, cancel)

    def stop_motion(self) -> list[str]:
        """Stop the arm now (never refused); returns the problems met."""
        arm = self.devices.arm
        if arm is None or not arm.is_connected:
            return []
        try:
            arm.stop()
        except Exception as exc:
            return [f"arm stop: {exc}"]
        self.runlog.event("arm/command", "stop", level="WARN")
        return []

    def emergency_stop(self) -> list[str]:
        """Software emergency stop: arm stopped, laser off. Not a substitute for the hardware
        emergency stop chain, which acts on the robot controller directly."""
        problems = self.make_safe()
        self.runlog.event("arm/command", "emergency stop (software)", level="ERROR")
        return problems

    def confirm_gripper_empty(self) -> None:
        """An operator removed the gripper's load by hand: open the gripper (it holds nothing
        now) and forget the cube in flight."""
        arm = self.devices.arm
        if arm is not None and arm.is_connected and arm.gripper.is_closed:
            arm.gripper.open()
        self.journal.clear_in_flight("an operator confirmed the gripper is empty")

    def check_safe_to_resume(self) -> ArmSafety | None:
        """Raise the driver's SafetyStopError if the arm is still in a stop; else its safety
        (None: no arm connected)."""
        arm = self.devices.arm
        if arm is None or not arm.is_connected:
            return None
        st = arm.safety_status()
        st.raise_if_stopped(arm.name)
        return ArmSafety(st.robot_mode, st.ok)
