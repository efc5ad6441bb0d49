"""The cell: the configured devices wired to calibration storage, the run log and the core.

The service calls one `Cell` from several threads: the job thread (one long command at a
time), the quick-command pool (status, capture, laser) and the safety pool (stop, estop).
Access to the camera and the laser switch is serialised with a lock each; `Arm.stop()` may
always be called concurrently with a motion (the driver contract says it always passes).
Status reads use short-lived caches so that many clients polling `status` never queue behind
a device.

Pipeline commands (calibrate, map, register_robot, locate, sort) call the core; until a core
component exists they raise `NotAvailableError` naming it, never a made-up result.
"""

from __future__ import annotations

import base64
import json
import logging
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from omnisort_hw import fileio
from omnisort_hw.errors import MotionRefusedError, OmnisortError
from omnisort_hw.runlog import RunLog
from omnisort_hw.storage import CalibrationStore

if TYPE_CHECKING:
    from drivers.base import Arm, Camera, LaserSwitch
    from omnisort_hw.service.config import Settings
    from omnisort_hw.service.rrd import RunLogRotator

log = logging.getLogger(__name__)

STATUS_CACHE_S = 0.05
STATUS_POLL_S = 0.1
CALIBRATION_CACHE_S = 1.0
LASER_CACHE_S = 1.0
DEVICE_LOCK_TIMEOUT_S = 5.0


class NotAvailableError(OmnisortError):
    """A command needs a component that is not in this build (the message names it)."""

    code = "not_available"


class DeviceLockTimeoutError(OmnisortError):
    """A device stayed busy with another command for longer than the lock timeout."""

    code = "busy"


@dataclass
class CellDevices:
    """The devices of one cell; a missing device is None (commands needing it say so)."""

    camera: Camera | None = None
    laser: LaserSwitch | None = None
    arm: Arm | None = None

    def items(self) -> list[tuple[str, Any]]:
        return [("camera", self.camera), ("laser", self.laser), ("arm", self.arm)]


@dataclass
class _Cached:
    value: Any = None
    at: float = -1e18

    def fresh(self, max_age_s: float) -> bool:
        return time.monotonic() - self.at <= max_age_s


@dataclass
class _Caches:
    arm: _Cached = field(default_factory=_Cached)
    laser: _Cached = field(default_factory=_Cached)
    calibration: _Cached = field(default_factory=_Cached)
    calibration_key: Any = None


def _iso(wall: float) -> str:
    return datetime.fromtimestamp(wall, UTC).isoformat(timespec="milliseconds")


def _error_text(exc: BaseException) -> dict[str, str]:
    return {"error": str(exc), "code": str(getattr(exc, "code", type(exc).__name__))}


class Cell:
    """Devices + calibration store + run log + core functions, for one robot cell."""

    def __init__(
        self,
        devices: CellDevices,
        store: CalibrationStore,
        runlog: RunLogRotator | RunLog | None = None,
        capture_dir: Path | None = None,
        capture_keep: int = 50,
        config: dict[str, Any] | None = None,
    ) -> None:
        self.devices = devices
        self.store = store
        self._runlog = runlog if runlog is not None else RunLog(None)
        self.capture_dir = capture_dir or Path(store.state_dir) / "captures"
        self.capture_keep = capture_keep
        self.config = dict(config or {})
        self._camera_lock = threading.Lock()
        self._laser_lock = threading.Lock()
        self._cache_lock = threading.Lock()
        self._caches = _Caches()
        self._connected = False
        self._motion_count = 0
        self._snapshot: dict[str, Any] | None = None
        self._snapshot_at = 0.0
        self._poller_stop = threading.Event()
        self._poller: threading.Thread | None = None

    # -- construction and life cycle -------------------------------------------------------

    @classmethod
    def from_settings(cls, settings: Settings) -> Cell:
        """Build the cell of a configuration: devices from the device factory, store, run log."""
        from omnisort_hw.service.rrd import RunLogRotator

        devices = open_devices(settings.raw, settings.path)
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
            config=settings.raw,
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
        """Start a new `.rrd` file if the current one is over its size limit (between jobs)."""
        rl = self._runlog
        return False if isinstance(rl, RunLog) else rl.roll_if_needed()

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
        self.runlog.event("service/devices", f"connected: {self.device_names()}")

    def device_names(self) -> dict[str, str | None]:
        return {name: (dev.name if dev is not None else None) for name, dev in self.devices.items()}

    def close(self) -> list[str]:
        """Safe shutdown: arm stopped, laser off, devices closed, run log flushed; never raises.

        Returns the problems met (also logged), so the caller can report them.
        """
        self._poller_stop.set()
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
    def _locked(self, lock: threading.Lock, what: str) -> Iterator[None]:
        if not lock.acquire(timeout=DEVICE_LOCK_TIMEOUT_S):
            raise DeviceLockTimeoutError(
                f"the {what} has been busy with another command for {DEVICE_LOCK_TIMEOUT_S:g} s"
            )
        try:
            yield
        finally:
            lock.release()

    def _cache_laser(self, on: bool) -> None:
        with self._cache_lock:
            self._caches.laser = _Cached(bool(on), time.monotonic())

    # -- status ----------------------------------------------------------------------------

    def calibration_status(self) -> dict[str, Any]:
        """`CalibrationStore.status()`, recomputed when a file changes or after one second."""
        key = []
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
            self._caches.calibration = _Cached(value, time.monotonic())
            self._caches.calibration_key = key
        return dict(value)

    def _arm_status(self) -> dict[str, Any]:
        arm = self.devices.arm
        if arm is None:
            return {"configured": False}
        with self._cache_lock:
            if self._caches.arm.fresh(STATUS_CACHE_S):
                return dict(self._caches.arm.value)
        out: dict[str, Any] = {"configured": True, "name": arm.name, "connected": arm.is_connected}
        if arm.is_connected:
            try:
                st = arm.state()
                out.update(
                    joints_deg=np.round(np.asarray(st.joints_deg, float), 4).tolist(),
                    tcp_pose=np.round(np.asarray(st.tcp_pose, float), 4).tolist(),
                    safety={
                        "ok": st.safety.ok,
                        "protective_stop": st.safety.protective_stop,
                        "emergency_stop": st.safety.emergency_stop,
                        "robot_mode": st.safety.robot_mode,
                        "safety_mode": getattr(st.safety, "safety_mode", None),
                    },
                )
            except Exception as exc:
                out.update(_error_text(exc))
        with self._cache_lock:
            self._caches.arm = _Cached(out, time.monotonic())
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
                out.update(_error_text(exc))
            finally:
                self._laser_lock.release()
        else:
            out["on"] = cached.value
            out["cached"] = True
        return out

    def _camera_status(self) -> dict[str, Any]:
        cam = self.devices.camera
        if cam is None:
            return {"configured": False}
        out: dict[str, Any] = {"configured": True, "name": cam.name, "connected": cam.is_connected}
        if cam.is_connected:
            try:
                out["serial"] = cam.serial
                out["resolution"] = list(cam.resolution)
            except Exception as exc:
                out.update(_error_text(exc))
        return out

    def read_status(self) -> dict[str, Any]:
        """Devices and calibration read now (device calls; the poller thread calls this)."""
        return {
            "devices": {
                "camera": self._camera_status(),
                "laser": self._laser_status(),
                "arm": self._arm_status(),
            },
            "calibration": self.calibration_status(),
            "rrd": str(self.runlog_path) if self.runlog_path else None,
        }

    def status(self) -> dict[str, Any]:
        """The latest status snapshot, never waiting for a device: the poller thread refreshes
        it every STATUS_POLL_S; `status_age_s` says how old it is. Without a poller (not
        connected) it is read now."""
        with self._cache_lock:
            snap, at = self._snapshot, self._snapshot_at
        if snap is None:
            return self.read_status()
        out = dict(snap)
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
        with self._locked(self._camera_lock, "camera"):
            frame = cam.grab(timeout_s)
        rl = self.runlog
        rl.set_step("frame", int(frame.sequence))
        rl.image("camera/raw", frame.image)
        return frame

    def set_laser(self, on: bool) -> bool:
        """Switch the laser (confirmed by the driver's read-back) and return the state."""
        laser = self._need("laser")
        with self._locked(self._laser_lock, "laser"):
            laser.set(bool(on))
            state = bool(laser.state())
        self._cache_laser(state)
        self.runlog.event("laser/state", "on" if state else "off")
        return state

    def laser(self, on: bool | None = None) -> dict[str, Any]:
        """Switch the laser when `on` is given; always read the state back."""
        laser = self._need("laser")
        if on is not None:
            return {"on": self.set_laser(on)}
        with self._locked(self._laser_lock, "laser"):
            state = bool(laser.state())
        self._cache_laser(state)
        return {"on": state}

    def capture(
        self, encoding: str = "path", fmt: str = "png", laser: bool | None = None
    ) -> dict[str, Any]:
        """Grab one image; return it as a file under `capture_dir` or as base64."""
        import cv2

        if laser is not None:
            self.set_laser(laser)
        frame = self.grab()
        ext = ".png" if fmt == "png" else ".jpg"
        ok, buf = cv2.imencode(ext, frame.image)
        if not ok:
            raise OmnisortError(f"could not encode the image as {fmt}")
        data = buf.tobytes()
        h, w = frame.image.shape[:2]
        result: dict[str, Any] = {
            "sequence": int(frame.sequence),
            "wall_time": _iso(frame.wall_time),
            "width": int(w),
            "height": int(h),
            "format": fmt,
            "bytes": len(data),
        }
        if encoding == "base64":
            result["base64"] = base64.b64encode(data).decode("ascii")
            return result
        stamp = datetime.fromtimestamp(frame.wall_time, UTC).strftime("%Y%m%dT%H%M%S.%fZ")
        path = self.capture_dir / f"capture-{stamp}-{int(frame.sequence):06d}{ext}"
        fileio.atomic_write_bytes(path, data, keep_history=False)
        self._prune_captures()
        result["path"] = str(path)
        return result

    def _prune_captures(self) -> None:
        files = sorted(self.capture_dir.glob("capture-*"))
        for old in files[: max(0, len(files) - self.capture_keep)]:
            old.unlink(missing_ok=True)

    # -- motion ----------------------------------------------------------------------------

    def check_motion_allowed(self) -> None:
        """Raise MotionRefusedError unless camera.json and system.json are usable."""
        self.store.check_motion_allowed()

    def move(
        self,
        joints_deg: Sequence[float] | None = None,
        pose: Sequence[float] | None = None,
        matrix: Sequence[Sequence[float]] | None = None,
        speed_deg_s: float | None = None,
        speed_mm_s: float | None = None,
        cancel: threading.Event | None = None,
    ) -> dict[str, Any]:
        """Move to a joint target (joint space) or a Cartesian target (straight TCP line).

        Refused before anything reaches the arm when the calibration is not usable or the arm
        reports a safety stop; the driver checks its joint limits and workspace box itself.
        """
        from drivers.base import pose_matrix

        arm = self._need("arm")
        self.check_motion_allowed()
        arm.safety_status().raise_if_stopped(arm.name)
        _raise_if_cancelled(cancel)
        rl = self.runlog
        start = np.asarray(arm.joint_positions(), float)
        sampler = _JointSampler(arm)
        if joints_deg is not None:
            target = np.asarray(joints_deg, float)
            rl.event("arm/command", f"move_joints to {np.round(target, 3).tolist()} deg")
            try:
                self._log_planned_joint_move(start, target, speed_deg_s)
            except Exception as exc:
                log.warning("could not log the planned trajectory: %s", exc)
            _raise_if_cancelled(cancel)
            with sampler:
                arm.move_joints(target, speed_deg_s=speed_deg_s)
        else:
            T = np.asarray(matrix, float) if matrix is not None else None
            if T is None:
                p = np.asarray(pose, float)
                T = pose_matrix(p[:3], p[3:])
            rl.event("arm/command", f"move_linear to xyz {np.round(T[:3, 3], 2).tolist()} mm")
            rl.pose("arm/planned/tcp", T)
            _raise_if_cancelled(cancel)
            with sampler:
                arm.move_linear(T, speed_mm_s=speed_mm_s)
        end = np.asarray(arm.joint_positions(), float)
        tcp = np.asarray(arm.tcp_pose(), float)
        self._log_joint_series("arm/executed", sampler.times, sampler.samples)
        rl.pose("arm/executed/tcp", tcp)
        return {"joints_deg": np.round(end, 4).tolist(), "tcp_pose": np.round(tcp, 4).tolist()}

    def _log_planned_joint_move(
        self, start: np.ndarray, target: np.ndarray, speed_deg_s: float | None
    ) -> None:
        """Log the joint trajectory the core's planner expects for this move (for review)."""
        from omnisort_hw.core.motion import MotionLimits as PlanLimits
        from omnisort_hw.core.motion import plan_joint_move

        limits = PlanLimits(joint_speed_deg_s=speed_deg_s) if speed_deg_s else PlanLimits()
        traj = plan_joint_move(start, target, limits)
        self._log_joint_series("arm/planned", traj.t, traj.q)

    def _log_joint_series(self, prefix: str, t: Sequence[float], q: np.ndarray) -> None:
        """Joint angles as scalars `PREFIX/q1..q6` on the `motion_ms` timeline, which counts
        milliseconds since the move began plus 10^6 times the move's number (one segment per
        move, planned and executed side by side)."""
        rl = self.runlog
        if not rl.enabled or len(t) == 0:
            return
        q = np.asarray(q, float).reshape(-1, 6)
        base = self._motion_count * 1_000_000
        for ti, qi in zip(t, q, strict=True):
            rl.set_step("motion_ms", base + round(float(ti) * 1000))
            for j in range(6):
                rl.scalar(f"{prefix}/q{j + 1}", float(qi[j]))
        if prefix.endswith("executed"):
            self._motion_count += 1

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

    def check_safe_to_resume(self) -> dict[str, Any]:
        """Raise the driver's SafetyStopError if the arm is still in a stop; else its safety."""
        arm = self.devices.arm
        if arm is None or not arm.is_connected:
            return {"arm": None}
        st = arm.safety_status()
        st.raise_if_stopped(arm.name)
        return {"arm": {"robot_mode": st.robot_mode, "ok": st.ok}}

    # -- pipeline (core) -------------------------------------------------------------------

    def calibrate_intrinsics(
        self,
        folder: str,
        board: str = "9x6",
        square_mm: float = 0.0,
        degree: int | None = None,
        cancel: threading.Event | None = None,
    ) -> dict[str, Any]:
        """Intrinsic calibration from the checkerboard images of `folder`, saved as camera.json.

        The images are taken to come from the camera attached now (its serial is stored).
        """
        import cv2

        from omnisort_hw.core.camera_io import camera_record
        from omnisort_hw.core.checkerboard import BoardSpec
        from omnisort_hw.core.intrinsics import calibrate_images
        from omnisort_hw.errors import InputError

        try:
            spec = BoardSpec.parse(board, square_mm)
        except ValueError as exc:
            raise InputError(f"calibrate: board/square_mm: {exc}") from None
        paths = image_files(folder)
        images = []
        for path in paths:
            _raise_if_cancelled(cancel, "calibration")
            image = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if image is None:
                raise InputError(f"{path}: not a readable image (unknown format or corrupt)")
            images.append((str(path), image))
        rl = self.runlog
        rl.event("calibration/intrinsics", f"{len(images)} images from {folder}, board {board}")
        result = calibrate_images(images, spec, degree=degree, log=rl)
        _raise_if_cancelled(cancel, "calibration")
        record = {
            **result.record(),
            "board": {"inner_corners": [spec.cols, spec.rows], "square_mm": spec.square_mm},
            "images_folder": str(folder),
            "created": datetime.now(UTC).isoformat(timespec="seconds"),
        }
        saved = self.store.save_camera(camera_record(result.model, **record))
        model = result.model
        rl.scalar("calibration/intrinsics/rms_px", result.rms_px)
        rl.text(
            "calibration/intrinsics/parameters",
            json.dumps({"model": model.to_dict(), "std": result.std}, indent=1, default=str),
        )
        return {
            "path": str(saved),
            "rms_px": result.rms_px,
            "images_used": len(result.images_used),
            "images_rejected": record["images_rejected"],
            "center_uv": list(model.center_uv),
            "poly_degree": result.degree,
            "camera_serial": self.store.expected_serial,
        }

    def _source_image(
        self, image: str | None, laser: bool = True
    ) -> tuple[np.ndarray, dict[str, Any], str]:
        """The image to work on: the file `image`, or a fresh capture (laser switched to
        `laser` first) saved under `capture_dir`. Returns (image, image record, source)."""
        from omnisort_hw.extrinsics_pipeline import image_record, read_image

        if image is not None:
            return read_image(image), image_record(image), str(image)
        captured = self.capture(encoding="path", fmt="png", laser=laser)
        path = captured["path"]
        return read_image(path), image_record(path), path

    def calibrate_extrinsics(
        self,
        image: str | None = None,
        target: str | None = None,
        method: str | None = None,
        separation_mm: float | None = None,
        board: str | None = None,
        square_mm: float | None = None,
        cancel: threading.Event | None = None,
    ) -> dict[str, Any]:
        """Camera rotation and laser plane from one image of the calibration target (a fresh
        capture with the laser on, or `image`), saved as system.json. The previous robot base
        pose is not carried over: it was registered with the previous camera rotation."""
        from omnisort_hw.errors import InputError

        target = target or self._config_target().get("kind")
        if target is None:
            raise InputError(
                "calibrate what=extrinsics needs target=two-sided|three-sided|checkerboards "
                "(or kind in the configuration's [target] section)"
            )
        model = self.store.camera_model()
        img, record, source = self._source_image(image)
        _raise_if_cancelled(cancel, "calibration")
        with core_component("calibrate what=extrinsics"):
            from omnisort_hw.extrinsics_pipeline import DEFAULT_SEPARATION_MM, calibrate_system

            separation = separation_mm or self._config_target().get(
                "separation_mm", DEFAULT_SEPARATION_MM
            )
            calib = calibrate_system(
                img,
                model,
                target,
                method,
                separation_mm=float(separation),
                board=_board_size(board or "9x6"),
                square_mm=square_mm or 97.0,
                source=source,
                log=self.runlog,
            )
        _raise_if_cancelled(cancel, "calibration")
        calib.image = record
        payload = calib.to_json()
        payload["elapsed_s"] = round(calib.elapsed_s, 4)
        saved = self.store.save_system(payload)
        return {
            "path": str(saved),
            "method": calib.method,
            "target": target,
            "parameters": calib.parameters(),
            "std": calib.std,
            "residuals": calib.residuals,
            "image": record,
        }

    def _config_target(self) -> dict[str, Any]:
        section = self.config.get("target", {})
        return dict(section) if isinstance(section, dict) else {}

    def system_calibration(self) -> Any:
        """The verified system.json as the core's SystemCalibration."""
        from omnisort_hw.core.extrinsics.common import SystemCalibration

        rec = self.store.read("system")
        return SystemCalibration.from_json(rec.payload, source=str(rec.path))

    def map_scene(
        self,
        image: str | None = None,
        cancel: threading.Event | None = None,
        with_points: bool = False,
    ) -> dict[str, Any]:
        """Laser map: the stripe's pixels -> points on the laser plane (S, mm) -> segments.

        `with_points` adds the points themselves (S, mm, 0.1 mm) and their pixels."""
        from omnisort_hw.extrinsics_pipeline import check_image_size

        calib = self.system_calibration()
        img, record, source = self._source_image(image)
        _raise_if_cancelled(cancel, "mapping")
        check_image_size(img, calib.model, source)
        with core_component("map"):
            from omnisort_hw.core.mapping import laser_map

            lmap = laser_map(img, calib)
        rl = self.runlog
        finite = lmap.points_S[np.all(np.isfinite(lmap.points_S), axis=1)]
        rl.image("map/image", img)
        rl.points2d("map/image/laser", lmap.pixels, color=(255, 0, 0), radius=1)
        rl.points3d("map/points_S", finite, color=(255, 0, 0))
        for i, seg in enumerate(lmap.segments):
            rl.points3d(f"map/segments/{i}", seg.points_S, color=(0, 200, 255))
        return {"image": record, **lmap.summary(with_points)}

    def register_robot(self, image: str | None, cancel: threading.Event) -> dict[str, Any]:
        """Robot base pose from the floor checkerboard, stored in system.json."""
        from omnisort_hw.sorting import service_register_robot

        return service_register_robot(self, image, cancel)

    def locate(
        self, image: str | None, colors: list[str] | None, cancel: threading.Event
    ) -> dict[str, Any]:
        """Objects and their poses in the robot base frame."""
        from omnisort_hw.sorting import service_locate

        return service_locate(self, image, colors, cancel)

    def sort(
        self,
        max_objects: int | None,
        colors: list[str] | None,
        cancel: threading.Event,
        progress: Callable[[dict[str, Any]], None] | None = None,
    ) -> dict[str, Any]:
        """Locate, pick and place every object by colour until done, `max_objects` or cancel."""
        from omnisort_hw.sorting import service_sort

        return service_sort(self, max_objects, colors, cancel, progress)


@contextmanager
def core_component(what: str) -> Iterator[None]:
    """Turn "this part of the core is not in the build yet" into NotAvailableError."""
    try:
        yield
    except ModuleNotFoundError as exc:
        if exc.name and exc.name.startswith("omnisort_hw."):
            raise NotAvailableError(f"{what}: {exc.name} is not in this build yet") from None
        raise


def _board_size(text: str) -> tuple[int, int]:
    from omnisort_hw.errors import InputError

    try:
        cols, rows = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InputError(f"board must look like 9x6 (inner corners), got {text!r}") from None
    return cols, rows


def _raise_if_cancelled(cancel: threading.Event | None, what: str = "move") -> None:
    if cancel is not None and cancel.is_set():
        raise MotionRefusedError(f"{what} cancelled")


IMAGE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"})


def image_files(folder: str | Path) -> list[Path]:
    """The image files of `folder`, sorted by name; InputError when there are none."""
    from omnisort_hw.errors import InputError

    path = Path(folder)
    if not path.is_dir():
        raise InputError(f"{path}: no such folder")
    files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
    if not files:
        raise InputError(f"{path}: no images ({', '.join(sorted(IMAGE_SUFFIXES))})")
    return files


class _JointSampler:
    """Samples the arm's joint positions every `period_s` while a motion runs (executed path)."""

    def __init__(self, arm: Arm, period_s: float = 0.05) -> None:
        self.arm = arm
        self.period_s = period_s
        self.times: list[float] = []
        self.samples: list[np.ndarray] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="joint-sampler", daemon=True)
        self._t0 = 0.0

    def _run(self) -> None:
        while True:
            try:
                q = np.asarray(self.arm.joint_positions(), float)
            except Exception:
                q = None
            if q is not None and q.shape == (6,):
                self.times.append(time.monotonic() - self._t0)
                self.samples.append(q)
            if self._stop.wait(self.period_s):
                return

    def __enter__(self) -> _JointSampler:
        self._t0 = time.monotonic()
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        try:
            q = np.asarray(self.arm.joint_positions(), float)
            self.times.append(time.monotonic() - self._t0)
            self.samples.append(q)
        except Exception:
            return


def open_devices(config: dict[str, Any], config_path: Path | None = None) -> CellDevices:
    """The (unconnected) devices of the `[camera]`, `[laser]` and `[arm]` sections.

    `omnisort_hw.devices` picks the real driver or the simulated cell per section's `backend`
    and raises ConfigError naming the key when a section is wrong.
    """
    from omnisort_hw.devices import open_devices as build

    made = build(config, config_path)
    return CellDevices(camera=made.camera, laser=made.laser, arm=made.arm)
