"""Device interfaces shared by the real drivers (`drivers/`) and the simulated cell (`sim_backend`).

One abstract class per kind of device, in the style of lerobot's device packages:

* `connect()` and `close()` are idempotent; `is_connected` says which state the device is in;
  every device is a context manager (`with camera: ...` connects and closes).
* Every blocking call takes a timeout with a sensible default and raises a typed error from
  `drivers.errors` when it runs out; nothing blocks forever.
* Units at this interface: millimetres and degrees. A TCP pose is a 4x4 homogeneous matrix
  `T_base_tcp` whose translation is in millimetres (the UR driver converts to metres and
  rotation vectors in radians at its own boundary). `pose_matrix()` and `pose_vector()` convert
  to and from `[x, y, z mm, rx, ry, rz deg]` (rotation vector) for people and config files.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from types import TracebackType
from typing import Self

import numpy as np

from drivers.errors import MotionLimitError, SafetyStopError, UnsupportedError
from omnisort_hw.core.frames import pose_from_xyz_rotvec, xyz_rotvec_from_pose

DEFAULT_GRAB_TIMEOUT_S = 2.0
DEFAULT_SWITCH_TIMEOUT_S = 1.0
DEFAULT_MOVE_TIMEOUT_S = 60.0
DEFAULT_GRIPPER_TIMEOUT_S = 3.0


@dataclass(frozen=True)
class Frame:
    """One camera image. `timestamp` is `time.monotonic()` at capture (use it for ordering and
    latency); `wall_time` is `time.time()` (use it for logs); `sequence` counts frames since
    `connect()` and never repeats within a connection."""

    image: np.ndarray
    timestamp: float
    wall_time: float
    sequence: int

    @classmethod
    def now(cls, image: np.ndarray, sequence: int) -> Frame:
        """A frame stamped with the current monotonic and wall clocks."""
        return cls(
            image=image, timestamp=time.monotonic(), wall_time=time.time(), sequence=sequence
        )


@dataclass(frozen=True)
class SafetyStatus:
    """The arm's safety state as the controller reports it.

    `robot_mode` is the controller's mode name (UR: "RUNNING", "IDLE", "POWER_OFF", ...; sim:
    "RUNNING"); `safety_mode` the safety mode name ("NORMAL", "PROTECTIVE_STOP", ...).
    """

    protective_stop: bool
    emergency_stop: bool
    robot_mode: str
    safety_mode: str = "NORMAL"

    @property
    def ok(self) -> bool:
        """True when neither stop is active."""
        return not (self.protective_stop or self.emergency_stop)

    def raise_if_stopped(self, device: str) -> None:
        """Raise `SafetyStopError` (emergency first) when a stop is active."""
        state = f"{self.safety_mode}, robot mode {self.robot_mode}"
        if self.emergency_stop:
            raise SafetyStopError(
                f"arm at {device} is in EMERGENCY STOP ({state}): release the emergency stop "
                "button, then power on and release the brakes on the teach pendant",
                kind="emergency",
                device=device,
            )
        if self.protective_stop:
            raise SafetyStopError(
                f"arm at {device} is in a PROTECTIVE STOP ({state}): find and remove the cause "
                "(collision, limit), then unlock the protective stop on the teach pendant",
                kind="protective",
                device=device,
            )


def _vec(values: object, n: int, what: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise MotionLimitError(f"{what} must be {n} finite numbers, got {values!r}; nothing sent")
    return arr


# The rates `MotionLimits.check_rate` knows: name -> what it is, for messages.
RATES = {
    "joint_speed_deg_s": "joint speed (deg/s)",
    "joint_accel_deg_s2": "joint acceleration (deg/s^2)",
    "linear_speed_mm_s": "linear speed (mm/s)",
    "linear_accel_mm_s2": "linear acceleration (mm/s^2)",
}


@dataclass(frozen=True)
class MotionLimits:
    """Joint limits (deg), a workspace box (mm, base frame) and the highest speeds and
    accelerations, checked before any motion is sent.

    Every arm, real or simulated, calls `check_joints` / `check_pose` and `check_rate` before
    moving, so a target outside the limits or a speed or acceleration above the configured
    maximum (`[arm].max_*`) raises `MotionLimitError` and nothing reaches the controller.
    """

    joint_min_deg: tuple[float, ...] = (-360.0,) * 6
    joint_max_deg: tuple[float, ...] = (360.0,) * 6
    workspace_min_mm: tuple[float, float, float] = (-1000.0, -1000.0, -100.0)
    workspace_max_mm: tuple[float, float, float] = (1000.0, 1000.0, 1200.0)
    max_joint_speed_deg_s: float = 180.0
    max_joint_accel_deg_s2: float = 300.0
    max_linear_speed_mm_s: float = 1000.0
    max_linear_accel_mm_s2: float = 3000.0

    def check_rate(self, name: str, value: float | None, default: float) -> float:
        """`value` (or `default` when None) if it is in (0, max_<name>], else MotionLimitError
        naming the configuration key. `name` is one of `RATES`."""
        what = RATES[name]
        cap = float(getattr(self, f"max_{name}"))
        v = default if value is None else float(value)
        if not (np.isfinite(v) and 0 < v <= cap):
            raise MotionLimitError(
                f"{what} {v} is outside (0, {cap:g}] set by [arm].max_{name}; nothing sent"
            )
        return v

    def check_joints(self, q_deg: object) -> np.ndarray:
        """Return `q_deg` as a (6,) float array or raise `MotionLimitError` naming bad joints."""
        q = _vec(q_deg, 6, "joint target (deg)")
        lo, hi = np.asarray(self.joint_min_deg), np.asarray(self.joint_max_deg)
        bad = np.flatnonzero((q < lo) | (q > hi))
        if bad.size:
            parts = ", ".join(
                f"joint {i + 1} = {q[i]:.2f} deg not in [{lo[i]:.1f}, {hi[i]:.1f}]" for i in bad
            )
            raise MotionLimitError(f"joint target outside the joint limits: {parts}; nothing sent")
        return q

    def check_position(self, xyz_mm: object) -> np.ndarray:
        """Return the position as a (3,) array, or raise `MotionLimitError` if outside the box."""
        p = _vec(xyz_mm, 3, "position (mm)")
        lo, hi = np.asarray(self.workspace_min_mm), np.asarray(self.workspace_max_mm)
        bad = np.flatnonzero((p < lo) | (p > hi))
        if bad.size:
            parts = ", ".join(
                f"{'xyz'[i]} = {p[i]:.1f} mm not in [{lo[i]:.1f}, {hi[i]:.1f}]" for i in bad
            )
            raise MotionLimitError(f"target outside the workspace box: {parts}; nothing sent")
        return p

    def check_pose(self, pose: object) -> np.ndarray:
        """Validate a 4x4 `T_base_tcp` (mm) against the workspace box; return it as float array."""
        T = as_pose_matrix(pose)
        self.check_position(T[:3, 3])
        return T


def as_pose_matrix(pose: object) -> np.ndarray:
    """Return `pose` as a proper 4x4 rigid transform, or raise `MotionLimitError`."""
    T = np.asarray(pose, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise MotionLimitError(
            f"pose must be a finite 4x4 matrix (mm), got shape {T.shape}; nothing sent"
        )
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) <= 0:
        raise MotionLimitError("pose rotation is not a proper rotation matrix; nothing sent")
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0]):
        raise MotionLimitError("pose last row must be [0, 0, 0, 1]; nothing sent")
    return T


def pose_matrix(xyz_mm: object, rotvec_deg: object) -> np.ndarray:
    """4x4 `T_base_tcp` from a position (mm) and a rotation vector (axis * angle, degrees)."""
    return pose_from_xyz_rotvec(np.asarray(xyz_mm, float), np.asarray(rotvec_deg, float))


def pose_vector(T: object) -> np.ndarray:
    """`[x, y, z mm, rx, ry, rz deg]` (rotation vector) from a 4x4 `T_base_tcp` in mm."""
    xyz, rv = xyz_rotvec_from_pose(np.asarray(T, float))
    return np.concatenate([xyz, rv])


class Device(ABC):
    """Common life cycle: idempotent `connect()`/`close()`, `is_connected`, context manager."""

    @property
    @abstractmethod
    def name(self) -> str:
        """Where the device is (path, port, host), used in every error message."""

    @property
    @abstractmethod
    def is_connected(self) -> bool:
        """True between a successful `connect()` and `close()` (or a detected disconnection)."""

    @abstractmethod
    def connect(self) -> None:
        """Open the device; a second call while connected does nothing. Raises a `DeviceError`."""

    @abstractmethod
    def close(self) -> None:
        """Release the device; safe to call any number of times and after a failure."""

    def __enter__(self) -> Self:
        self.connect()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


# Pixel formats without lossy compression, best first: full-resolution colour, then YUYV
# (uncompressed, but its chroma is shared by two horizontal pixels), then grey.
UNCOMPRESSED_FORMATS = ("BGR3", "RGB3", "YUYV", "UYVY", "GREY")


class Camera(Device):
    """A colour camera. `grab()` always returns a frame captured after the call started."""

    @abstractmethod
    def grab(self, timeout_s: float | None = None) -> Frame:
        """Capture a fresh BGR uint8 HxWx3 frame (never a stale buffered one).

        `timeout_s=None` uses the device's configured read timeout. Raises `DeviceTimeoutError`
        when no frame arrives in time and `DeviceDisconnectedError` when the source is gone.
        """

    @property
    @abstractmethod
    def resolution(self) -> tuple[int, int]:
        """(width, height) in pixels of the frames `grab()` returns."""

    @property
    @abstractmethod
    def serial(self) -> str:
        """A stable identifier of the physical camera, used to detect a swapped camera."""

    @property
    def tone_curve(self) -> str:
        """The camera's transfer curve from light to pixel value, as a `ToneCurve.parse` spec
        (srgb, linear, gamma:G or a measured table's JSON file). Edge location undoes it, as a
        blurred step is antisymmetric only in light; sRGB is what 8-bit cameras write."""
        return "srgb"

    def get_exposure_ms(self) -> float:
        """Current manual exposure time in milliseconds."""
        raise UnsupportedError(f"camera {self.name} has no readable exposure", device=self.name)

    def set_exposure_ms(self, exposure_ms: float) -> None:
        """Switch to manual exposure and set it (ms); raises `UnsupportedError` if not possible."""
        raise UnsupportedError(f"camera {self.name} has no manual exposure", device=self.name)

    def get_gain(self) -> float:
        """Current analogue gain in the device's own units."""
        raise UnsupportedError(f"camera {self.name} has no readable gain", device=self.name)

    def set_gain(self, gain: float) -> None:
        """Set the analogue gain (device units); raises `UnsupportedError` if not possible."""
        raise UnsupportedError(f"camera {self.name} has no gain control", device=self.name)

    @property
    def pixel_formats(self) -> tuple[str, ...]:
        """The FOURCCs this camera can deliver (e.g. "MJPG", "YUYV"); empty when it cannot
        tell (files and streams deliver what they hold)."""
        return ()

    @property
    def pixel_format(self) -> str:
        """The FOURCC of the frames `grab()` returns now ("" when unknown)."""
        return ""

    def set_pixel_format(self, fourcc: str) -> None:
        """Switch the delivered pixel format; raises `UnsupportedError` if not possible."""
        raise UnsupportedError(
            f"camera {self.name} cannot switch its pixel format to {fourcc}", device=self.name
        )

    @property
    def exposure_ms(self) -> float:
        """Manual exposure in milliseconds (property form of `get_/set_exposure_ms`)."""
        return self.get_exposure_ms()

    @exposure_ms.setter
    def exposure_ms(self, value: float) -> None:
        self.set_exposure_ms(value)

    @property
    def gain(self) -> float:
        """Gain in device units (property form of `get_/set_gain`)."""
        return self.get_gain()

    @gain.setter
    def gain(self, value: float) -> None:
        self.set_gain(value)


class LaserSwitch(Device):
    """The laser line emitter's on/off switch. Every switch is confirmed by reading it back."""

    @abstractmethod
    def set(self, on: bool, timeout_s: float | None = None) -> None:
        """Switch the laser and confirm the new state; `timeout_s=None` uses the configured one.

        Raises `DeviceTimeoutError`, `BadReplyError` or `DeviceDisconnectedError`; on return the
        read-back state equals `on`.
        """

    @abstractmethod
    def state(self, timeout_s: float | None = None) -> bool:
        """Read the actual state from the device (True = laser on)."""

    def on(self, timeout_s: float | None = None) -> None:
        """Switch the laser on (confirmed)."""
        self.set(True, timeout_s)

    def off(self, timeout_s: float | None = None) -> None:
        """Switch the laser off (confirmed)."""
        self.set(False, timeout_s)


class Gripper(ABC):
    """The arm's end effector (two-finger gripper or suction cup). Owned by its `Arm`."""

    @abstractmethod
    def open(self, timeout_s: float = DEFAULT_GRIPPER_TIMEOUT_S) -> None:
        """Open (release suction) and wait until done or `timeout_s` runs out."""

    @abstractmethod
    def close(self, timeout_s: float = DEFAULT_GRIPPER_TIMEOUT_S) -> None:
        """Close (suction on) and wait until done or `timeout_s` runs out."""

    @property
    @abstractmethod
    def is_closed(self) -> bool:
        """True when the last command was close (the output is on)."""

    @property
    @abstractmethod
    def holding(self) -> bool | None:
        """True/False when the gripper can sense an object, None when it cannot tell."""


# The largest blend radius a path may ask for (UR's, 2 m).
MAX_BLEND_MM = 2000.0


@dataclass(frozen=True)
class Waypoint:
    """One row of a blended path, as UR's `moveJ(path)` / `moveL(path)` rows [target, speed,
    acceleration, blend]: "joint" to `target` (6,) deg at deg/s, deg/s^2, or "linear" to the
    TCP pose `target` (4x4 `T_base_tcp`, mm) at mm/s, mm/s^2 (None: the configured defaults).
    The arm passes within `blend_mm` of the target without stopping there (0: it stops); the
    last waypoint of a path always stops."""

    kind: str
    target: object
    speed: float | None = None
    accel: float | None = None
    blend_mm: float = 0.0


def check_path(limits: MotionLimits, path: object) -> list[Waypoint]:
    """The waypoints of `path`, each target checked (`check_joints` / `check_pose`) and each
    blend radius in [0, MAX_BLEND_MM], else `MotionLimitError` naming the waypoint."""
    points = list(path)  # type: ignore[call-overload]
    if not points:
        raise MotionLimitError("a path needs at least one waypoint; nothing sent")
    out = []
    for i, w in enumerate(points):
        if not isinstance(w, Waypoint) or w.kind not in ("joint", "linear"):
            raise MotionLimitError(
                f"path waypoint {i}: not a joint or linear Waypoint; nothing sent"
            )
        blend = float(w.blend_mm)
        if not (np.isfinite(blend) and 0.0 <= blend <= MAX_BLEND_MM):
            raise MotionLimitError(
                f"path waypoint {i}: blend radius {w.blend_mm} mm is not in [0, {MAX_BLEND_MM:g}]"
                " mm; nothing sent"
            )
        try:
            target = (
                limits.check_joints(w.target) if w.kind == "joint" else limits.check_pose(w.target)
            )
        except MotionLimitError as exc:
            raise MotionLimitError(f"path waypoint {i}: {exc}") from None
        out.append(
            Waypoint(w.kind, target, w.speed, w.accel, blend if i < len(points) - 1 else 0.0)
        )
    return out


@dataclass(frozen=True)
class ArmState:
    """A snapshot for status displays: joints (deg), TCP pose (4x4, mm) and safety."""

    joints_deg: np.ndarray
    tcp_pose: np.ndarray
    safety: SafetyStatus
    extra: dict[str, object] = field(default_factory=dict)


class Arm(Device):
    """A 6-axis arm in millimetres and degrees.

    Motions block until finished or until `timeout_s`; before anything is sent the target is
    checked against `limits` (raising `MotionLimitError`) and the safety status is checked
    (raising `SafetyStopError`). `stop()` always passes, whatever the state.
    """

    @property
    @abstractmethod
    def limits(self) -> MotionLimits:
        """The joint limits and workspace box every motion is checked against."""

    @property
    @abstractmethod
    def gripper(self) -> Gripper:
        """The gripper mounted on this arm."""

    @abstractmethod
    def joint_positions(self) -> np.ndarray:
        """Actual joint positions, (6,) degrees."""

    @abstractmethod
    def tcp_pose(self) -> np.ndarray:
        """Actual TCP pose `T_base_tcp`, 4x4 homogeneous matrix, translation in millimetres."""

    @abstractmethod
    def move_joints(
        self,
        q_deg: object,
        speed_deg_s: float | None = None,
        accel_deg_s2: float | None = None,
        timeout_s: float = DEFAULT_MOVE_TIMEOUT_S,
    ) -> None:
        """Move in joint space to `q_deg` (6,) degrees; None speed/accel = configured defaults."""

    @abstractmethod
    def move_linear(
        self,
        pose: object,
        speed_mm_s: float | None = None,
        accel_mm_s2: float | None = None,
        timeout_s: float = DEFAULT_MOVE_TIMEOUT_S,
    ) -> None:
        """Move the TCP in a straight line to `pose` (4x4 `T_base_tcp`, mm)."""

    def move_path(self, path: object, timeout_s: float = DEFAULT_MOVE_TIMEOUT_S) -> None:
        """Move through `path` (a sequence of `Waypoint`), blending past each waypoint within
        its blend radius. Nothing is sent unless every waypoint passes the checks. An arm
        whose controller cannot blend stops at every waypoint (this default)."""
        points = check_path(self.limits, path)
        deadline = time.monotonic() + timeout_s
        for w in points:
            left = max(deadline - time.monotonic(), 1e-3)
            if w.kind == "joint":
                self.move_joints(w.target, w.speed, w.accel, timeout_s=left)
            else:
                self.move_linear(w.target, w.speed, w.accel, timeout_s=left)

    @abstractmethod
    def stop(self) -> None:
        """Decelerate and stop any motion now. Never refused."""

    @abstractmethod
    def safety_status(self) -> SafetyStatus:
        """Protective stop, emergency stop and robot mode as the controller reports them."""

    def state(self) -> ArmState:
        """Joints, TCP pose and safety in one record."""
        return ArmState(self.joint_positions(), self.tcp_pose(), self.safety_status())


__all__ = [
    "DEFAULT_GRAB_TIMEOUT_S",
    "DEFAULT_GRIPPER_TIMEOUT_S",
    "DEFAULT_MOVE_TIMEOUT_S",
    "DEFAULT_SWITCH_TIMEOUT_S",
    "MAX_BLEND_MM",
    "RATES",
    "UNCOMPRESSED_FORMATS",
    "Arm",
    "ArmState",
    "Camera",
    "Device",
    "Frame",
    "Gripper",
    "LaserSwitch",
    "MotionLimits",
    "SafetyStatus",
    "Waypoint",
    "as_pose_matrix",
    "check_path",
    "pose_matrix",
    "pose_vector",
]
