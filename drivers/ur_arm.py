"""UR arm over RTDE: millimetres and degrees outside, metres, radians and rotation vectors inside.

Every motion goes through the same gate, in this order:

1. the target and the requested speed/acceleration are checked against `[arm]` limits (joint
   limits, the workspace box, speed/acceleration caps); a violation raises `MotionLimitError`
   and nothing at all reaches the controller link;
2. the link is (re)connected if it dropped — a reconnect never resends an interrupted motion;
3. the safety status is read; a protective or emergency stop raises `SafetyStopError`, any
   robot mode other than RUNNING raises `DeviceNotReadyError`;
4. the move is started asynchronously and polled every `poll_period_s` until it ends, the
   timeout runs out (the arm is stopped, `DeviceTimeoutError`), a safety stop appears
   (`SafetyStopError`) or the link drops (`DeviceDisconnectedError`); the final position is
   checked against the target.

Only the target is checked against the workspace box: a linear move between two points of a
box stays in it; a joint move's path can leave it, so keep the box conservative.
The controller is reached only through `drivers.ur_rtde_adapter.URLink`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from drivers._common import Backoff, require
from drivers.base import (
    DEFAULT_GRIPPER_TIMEOUT_S,
    DEFAULT_MOVE_TIMEOUT_S,
    Arm,
    Gripper,
    MotionLimits,
    SafetyStatus,
    check_path,
    pose_matrix,
    pose_vector,
)
from drivers.errors import (
    DeviceDisconnectedError,
    DeviceError,
    DeviceNotReadyError,
    DeviceTimeoutError,
)
from drivers.ur_rtde_adapter import IOKind, URLink
from drivers.ur_rtde_worker import ROBOT_MODE_RUNNING

log = logging.getLogger("drivers.arm")

ROBOT_MODES = {
    -1: "NO_CONTROLLER",
    0: "DISCONNECTED",
    1: "CONFIRM_SAFETY",
    2: "BOOTING",
    3: "POWER_OFF",
    4: "POWER_ON",
    5: "IDLE",
    6: "BACKDRIVE",
    7: "RUNNING",
    8: "UPDATING_FIRMWARE",
}
SAFETY_MODES = {
    1: "NORMAL",
    2: "REDUCED",
    3: "PROTECTIVE_STOP",
    4: "RECOVERY",
    5: "SAFEGUARD_STOP",
    6: "SYSTEM_EMERGENCY_STOP",
    7: "ROBOT_EMERGENCY_STOP",
    8: "VIOLATION",
    9: "FAULT",
    10: "VALIDATE_JOINT_ID",
    11: "UNDEFINED_SAFETY_MODE",
    12: "AUTOMATIC_MODE_SAFEGUARD_STOP",
    13: "SYSTEM_THREE_POSITION_ENABLING_STOP",
}
# The most ur-rtde passes to the controller (its UR_JOINT_VELOCITY_MAX 3.14 rad/s,
# UR_JOINT_ACCELERATION_MAX 40 rad/s^2, UR_TOOL_VELOCITY_MAX 3 m/s, UR_TOOL_ACCELERATION_MAX
# 150 m/s^2); a move above them is refused inside ur-rtde, so the caps may not exceed them.
RTDE_CAPS = {
    "max_joint_speed_deg_s": float(np.degrees(3.14)),
    "max_joint_accel_deg_s2": float(np.degrees(40.0)),
    "max_linear_speed_mm_s": 3000.0,
    "max_linear_accel_mm_s2": 150000.0,
}
_EMERGENCY = {6, 7}
_PROTECTIVE = {3, 4, 5, 8, 9, 12, 13}


@dataclass(frozen=True)
class URArmConfig:
    """Settings of `[arm]` with `backend = "ur_rtde"`. Lengths in mm, angles in degrees.

    The gripper is a digital output (`gripper_io` "tool", "standard" or "configurable", pin
    `gripper_pin`); `gripper_closed_level` is the output level that closes it (or switches
    suction on); `gripper_sense_pin >= 0` names a digital input of the same kind that reads
    True when an object is held (else `holding` is None).
    """

    SECTION: ClassVar[str] = "arm"

    host: str = "192.168.1.10"
    connect_timeout_s: float = 10.0
    joint_speed_deg_s: float = 60.0
    joint_accel_deg_s2: float = 80.0
    linear_speed_mm_s: float = 250.0
    linear_accel_mm_s2: float = 1000.0
    max_joint_speed_deg_s: float = 179.9
    max_joint_accel_deg_s2: float = 300.0
    max_linear_speed_mm_s: float = 1000.0
    max_linear_accel_mm_s2: float = 3000.0
    stop_decel_deg_s2: float = 300.0
    joint_min_deg: tuple[float, ...] = (-360.0,) * 6
    joint_max_deg: tuple[float, ...] = (360.0,) * 6
    workspace_min_mm: tuple[float, ...] = (-800.0, -800.0, -50.0)
    workspace_max_mm: tuple[float, ...] = (800.0, 800.0, 900.0)
    joint_tolerance_deg: float = 0.2
    position_tolerance_mm: float = 1.0
    poll_period_s: float = 0.02
    gripper_io: IOKind = "tool"
    gripper_pin: int = 0
    gripper_closed_level: bool = True
    gripper_settle_s: float = 0.3
    gripper_sense_pin: int = -1
    reconnect_attempts: int = 3
    reconnect_backoff_s: float = 0.5
    call_timeout_s: float = 2.0
    state_timeout_s: float = 0.5

    def __post_init__(self) -> None:
        s = self.SECTION
        require(bool(self.host), s, "host", "give the controller's IP address")
        for key in (
            "connect_timeout_s",
            "joint_speed_deg_s",
            "joint_accel_deg_s2",
            "linear_speed_mm_s",
            "linear_accel_mm_s2",
            "max_joint_speed_deg_s",
            "max_joint_accel_deg_s2",
            "max_linear_speed_mm_s",
            "max_linear_accel_mm_s2",
            "stop_decel_deg_s2",
            "joint_tolerance_deg",
            "position_tolerance_mm",
            "poll_period_s",
            "reconnect_backoff_s",
            "call_timeout_s",
            "state_timeout_s",
        ):
            require(getattr(self, key) > 0, s, key, f"must be > 0, got {getattr(self, key)}")
        require(self.gripper_settle_s >= 0, s, "gripper_settle_s", "must be >= 0")
        for key, cap in RTDE_CAPS.items():
            require(
                getattr(self, key) <= cap,
                s,
                key,
                f"must not exceed {cap:g}, the most ur-rtde sends (got {getattr(self, key)})",
            )
        require(
            self.joint_speed_deg_s <= self.max_joint_speed_deg_s,
            s,
            "joint_speed_deg_s",
            "must not exceed max_joint_speed_deg_s",
        )
        require(
            self.linear_speed_mm_s <= self.max_linear_speed_mm_s,
            s,
            "linear_speed_mm_s",
            "must not exceed max_linear_speed_mm_s",
        )
        for key, n in (
            ("joint_min_deg", 6),
            ("joint_max_deg", 6),
            ("workspace_min_mm", 3),
            ("workspace_max_mm", 3),
        ):
            require(len(getattr(self, key)) == n, s, key, f"must have {n} numbers")
        require(
            all(a < b for a, b in zip(self.joint_min_deg, self.joint_max_deg, strict=True)),
            s,
            "joint_min_deg",
            "each joint minimum must be below its maximum",
        )
        require(
            all(a < b for a, b in zip(self.workspace_min_mm, self.workspace_max_mm, strict=True)),
            s,
            "workspace_min_mm",
            "each workspace minimum must be below its maximum",
        )
        require(
            self.gripper_io in ("tool", "standard", "configurable"),
            s,
            "gripper_io",
            "must be 'tool', 'standard' or 'configurable'",
        )
        pins = 2 if self.gripper_io == "tool" else 8
        require(0 <= self.gripper_pin < pins, s, "gripper_pin", f"must be 0..{pins - 1}")
        require(-1 <= self.gripper_sense_pin < pins, s, "gripper_sense_pin", f"-1 or 0..{pins - 1}")
        require(self.reconnect_attempts >= 1, s, "reconnect_attempts", "must be >= 1")

    def limits(self) -> MotionLimits:
        return MotionLimits(
            joint_min_deg=tuple(self.joint_min_deg),
            joint_max_deg=tuple(self.joint_max_deg),
            workspace_min_mm=tuple(self.workspace_min_mm),  # type: ignore[arg-type]
            workspace_max_mm=tuple(self.workspace_max_mm),  # type: ignore[arg-type]
            max_joint_speed_deg_s=self.max_joint_speed_deg_s,
            max_joint_accel_deg_s2=self.max_joint_accel_deg_s2,
            max_linear_speed_mm_s=self.max_linear_speed_mm_s,
            max_linear_accel_mm_s2=self.max_linear_accel_mm_s2,
        )


def tcp_matrix_from_ur(pose: list[float]) -> np.ndarray:
    """4x4 `T_base_tcp` in mm from a UR pose [m, rotvec rad]."""
    p = np.asarray(pose, dtype=float)
    return pose_matrix(p[:3] * 1000.0, np.rad2deg(p[3:]))


def ur_pose_from_matrix(T: np.ndarray) -> list[float]:
    """UR pose [x, y, z m, rx, ry, rz rad] from a 4x4 `T_base_tcp` in mm."""
    v = pose_vector(T)
    return [*(v[:3] / 1000.0), *np.deg2rad(v[3:])]


class URGripper(Gripper):
    """A gripper (or suction valve) on one digital output of the UR controller."""

    def __init__(self, arm: URArm) -> None:
        self._arm = arm

    def _drive(self, closed: bool, timeout_s: float) -> None:
        cfg = self._arm.config
        level = cfg.gripper_closed_level if closed else not cfg.gripper_closed_level
        deadline = time.monotonic() + timeout_s
        with self._arm._lock:
            link = self._arm._ready_link()
            link.set_output(cfg.gripper_io, cfg.gripper_pin, level)
            while link.output(cfg.gripper_io, cfg.gripper_pin) != level:
                if time.monotonic() >= deadline:
                    raise DeviceTimeoutError(
                        f"gripper on {cfg.gripper_io} output {cfg.gripper_pin} of "
                        f"{self._arm.name} does not read back {int(level)} within "
                        f"{timeout_s:.1f} s: check [arm].gripper_io and gripper_pin",
                        device=cfg.host,
                    )
                time.sleep(cfg.poll_period_s)
        time.sleep(max(0.0, min(cfg.gripper_settle_s, deadline - time.monotonic())))

    def open(self, timeout_s: float = DEFAULT_GRIPPER_TIMEOUT_S) -> None:
        self._drive(False, timeout_s)

    def close(self, timeout_s: float = DEFAULT_GRIPPER_TIMEOUT_S) -> None:
        self._drive(True, timeout_s)

    @property
    def is_closed(self) -> bool:
        cfg = self._arm.config
        with self._arm._lock:
            level = self._arm._ready_link().output(cfg.gripper_io, cfg.gripper_pin)
        return level == cfg.gripper_closed_level

    @property
    def holding(self) -> bool | None:
        cfg = self._arm.config
        if cfg.gripper_sense_pin < 0:
            return None
        with self._arm._lock:
            return self._arm._ready_link().input(cfg.gripper_io, cfg.gripper_sense_pin)


class URArm(Arm):
    """A Universal Robots arm through a `URLink` (ur-rtde by default)."""

    def __init__(self, config: URArmConfig, link: URLink | None = None) -> None:
        self.config = config
        if link is None:
            from drivers.ur_rtde_adapter import RTDELink

            link = RTDELink(config.call_timeout_s, config.state_timeout_s)
        self._link = link
        self._limits = config.limits()
        self._gripper = URGripper(self)
        self._lock = threading.RLock()
        self._opened = False
        self._stop_requested = threading.Event()

    @property
    def name(self) -> str:
        return f"UR arm at {self.config.host}"

    @property
    def is_connected(self) -> bool:
        return self._opened and self._link.is_connected()

    @property
    def limits(self) -> MotionLimits:
        return self._limits

    @property
    def gripper(self) -> Gripper:
        return self._gripper

    def connect(self) -> None:
        with self._lock:
            if self._opened and self._link.is_connected():
                return
            self._link.open(self.config.host, self.config.connect_timeout_s)
            self._opened = True
            status = self.safety_status()
            log.info("%s connected: %s / %s", self.name, status.robot_mode, status.safety_mode)

    def close(self) -> None:
        with self._lock:
            if self._opened:
                self._opened = False
                self._link.close()

    def _ready_link(self) -> URLink:
        """The link, reconnected with bounded back-off if it dropped. Never resumes a motion."""
        if not self._opened:
            raise DeviceDisconnectedError(
                f"{self.name} is not connected: call connect() first", device=self.config.host
            )
        if self._link.is_connected():
            return self._link
        cfg = self.config
        backoff = Backoff(
            cfg.reconnect_backoff_s, 8 * cfg.reconnect_backoff_s, cfg.reconnect_attempts
        )
        while not backoff.exhausted():
            time.sleep(backoff.wait_s())
            log.warning(
                "%s: connection dropped, reconnect attempt %d/%d (no motion is resent)",
                self.name,
                backoff.count + 1,
                cfg.reconnect_attempts,
            )
            try:
                self._link.reconnect(cfg.connect_timeout_s)
            except DeviceError as exc:
                log.warning("%s: reconnect failed: %s", self.name, exc)
                backoff.failed()
                continue
            log.warning("%s: reconnected; the arm was not moved", self.name)
            return self._link
        raise DeviceDisconnectedError(
            f"{self.name}: connection lost and {cfg.reconnect_attempts} reconnect attempts "
            "failed: check the network cable and the controller",
            device=cfg.host,
        )

    def safety_status(self) -> SafetyStatus:
        with self._lock:
            link = self._ready_link()
            robot, safety = link.robot_mode(), link.safety_mode()
        return SafetyStatus(
            protective_stop=safety in _PROTECTIVE,
            emergency_stop=safety in _EMERGENCY,
            robot_mode=ROBOT_MODES.get(robot, f"MODE_{robot}"),
            safety_mode=SAFETY_MODES.get(safety, f"SAFETY_{safety}"),
        )

    def _check_ready(self) -> None:
        status = self.safety_status()
        status.raise_if_stopped(self.config.host)
        if status.robot_mode != ROBOT_MODES[ROBOT_MODE_RUNNING]:
            raise DeviceNotReadyError(
                f"{self.name} is not ready to move (robot mode {status.robot_mode}): power on "
                "and release the brakes on the teach pendant, and select Remote Control",
                device=self.config.host,
            )

    def joint_positions(self) -> np.ndarray:
        with self._lock:
            return np.rad2deg(np.asarray(self._ready_link().actual_q(), dtype=float))

    def tcp_pose(self) -> np.ndarray:
        with self._lock:
            return tcp_matrix_from_ur(self._ready_link().actual_tcp_pose())

    def move_joints(
        self,
        q_deg: object,
        speed_deg_s: float | None = None,
        accel_deg_s2: float | None = None,
        timeout_s: float = DEFAULT_MOVE_TIMEOUT_S,
    ) -> None:
        cfg = self.config
        q = self._limits.check_joints(q_deg)
        v = self._limits.check_rate("joint_speed_deg_s", speed_deg_s, cfg.joint_speed_deg_s)
        a = self._limits.check_rate("joint_accel_deg_s2", accel_deg_s2, cfg.joint_accel_deg_s2)
        with self._lock:
            self._check_ready()
            self._stop_requested.clear()
            self._link.move_j(list(np.deg2rad(q)), float(np.deg2rad(v)), float(np.deg2rad(a)))
            self._follow(timeout_s, "joint move", *self._arrival("joint", q))

    def move_linear(
        self,
        pose: object,
        speed_mm_s: float | None = None,
        accel_mm_s2: float | None = None,
        timeout_s: float = DEFAULT_MOVE_TIMEOUT_S,
    ) -> None:
        cfg = self.config
        T = self._limits.check_pose(pose)
        v = self._limits.check_rate("linear_speed_mm_s", speed_mm_s, cfg.linear_speed_mm_s)
        a = self._limits.check_rate("linear_accel_mm_s2", accel_mm_s2, cfg.linear_accel_mm_s2)
        with self._lock:
            self._check_ready()
            self._stop_requested.clear()
            self._link.move_l(ur_pose_from_matrix(T), v / 1000.0, a / 1000.0)
            self._follow(timeout_s, "linear move", *self._arrival("linear", T))

    def move_path(self, path: object, timeout_s: float = DEFAULT_MOVE_TIMEOUT_S) -> None:
        """ur-rtde's path call (`movePath`: movej/movel rows with their blend radii, run by
        the controller as one program); followed as a single move to the last waypoint."""
        cfg = self.config
        lim = self._limits
        rows: list[tuple[str, list[float]]] = []
        points = check_path(lim, path)
        for w in points:
            blend = w.blend_mm / 1000.0
            if w.kind == "joint":
                v = lim.check_rate("joint_speed_deg_s", w.speed, cfg.joint_speed_deg_s)
                a = lim.check_rate("joint_accel_deg_s2", w.accel, cfg.joint_accel_deg_s2)
                q = list(np.deg2rad(np.asarray(w.target, float)))
                rows.append(("joint", [*q, float(np.deg2rad(v)), float(np.deg2rad(a)), blend]))
            else:
                v = lim.check_rate("linear_speed_mm_s", w.speed, cfg.linear_speed_mm_s)
                a = lim.check_rate("linear_accel_mm_s2", w.accel, cfg.linear_accel_mm_s2)
                pose = ur_pose_from_matrix(np.asarray(w.target, float))
                rows.append(("linear", [*pose, v / 1000.0, a / 1000.0, blend]))
        last = points[-1]
        with self._lock:
            self._check_ready()
            self._stop_requested.clear()
            self._link.move_path(rows)
            self._follow(timeout_s, "blended path", *self._arrival(last.kind, last.target))

    def _arrival(self, kind: str, target: object) -> tuple[Callable[[], float], float, str]:
        """How far the arm is from a checked joint ("joint", deg) or pose ("linear", mm)
        target, the tolerance that counts as arrived there, and its unit (for `_follow`)."""
        cfg = self.config
        if kind == "joint":
            q = np.asarray(target, float)
            return (
                lambda: float(np.max(np.abs(self.joint_positions() - q))),
                cfg.joint_tolerance_deg,
                "deg",
            )
        p = np.asarray(target, float)[:3, 3]
        return (
            lambda: float(np.linalg.norm(self.tcp_pose()[:3, 3] - p)),
            cfg.position_tolerance_mm,
            "mm",
        )

    def _follow(
        self,
        timeout_s: float,
        what: str,
        error_fn: Callable[[], float],
        tolerance: float,
        unit: str,
    ) -> None:
        """Poll a running move until it ends; stop it on timeout, raise on stops and drops."""
        cfg = self.config
        deadline = time.monotonic() + timeout_s
        idle_since: float | None = None
        while True:
            if not self._link.is_connected():
                raise DeviceDisconnectedError(
                    f"{self.name}: connection lost during the {what}; the controller stops the "
                    "arm; the move is NOT resumed after reconnecting",
                    device=cfg.host,
                )
            self.safety_status().raise_if_stopped(cfg.host)
            if self._stop_requested.is_set():
                raise DeviceError(f"{self.name}: {what} interrupted by stop()", device=cfg.host)
            if not self._link.is_moving():
                rest = self._at_rest()  # read before the position: once at rest, it stays
                err = error_fn()
                if rest and err <= tolerance:
                    return
                now = time.monotonic()
                idle_since = idle_since if idle_since is not None else now
                # a pendant stop is judged after 0.5 s; the state stream is never older
                # than state_timeout_s (refused as stale), so its lag cannot pass for a stop
                if now - idle_since > 0.5 + cfg.state_timeout_s:
                    raise DeviceError(
                        f"{self.name}: {what} ended {err:.2f} {unit} from the target (stopped "
                        "from the pendant or by another client?)",
                        device=cfg.host,
                    )
            else:
                idle_since = None
            if time.monotonic() >= deadline:
                self._stop_now()
                raise DeviceTimeoutError(
                    f"{self.name}: {what} did not finish within {timeout_s:.1f} s; the arm was "
                    "stopped (raise the timeout or the speed)",
                    device=cfg.host,
                )
            time.sleep(cfg.poll_period_s)

    def _at_rest(self) -> bool:
        """The state stream shows the joints at rest: slower than one arrival tolerance per
        second. The motion's end is read from the control stream and the position from the
        receive stream; under load the receive stream can lag a few packages behind, and a
        position read from it mid-braking is not where the arm ends."""
        with self._lock:
            qd = np.rad2deg(np.asarray(self._ready_link().actual_qd(), dtype=float))
        return float(np.max(np.abs(qd))) <= self.config.joint_tolerance_deg

    def _stop_now(self) -> None:
        decel = float(np.deg2rad(self.config.stop_decel_deg_s2))
        self._link.stop_j(decel)

    def stop(self) -> None:
        """Stop now; no limit or safety check, never refused. Raises only if the link is down."""
        if not self._link.is_connected():
            raise DeviceDisconnectedError(
                f"{self.name}: cannot send stop, the connection is down (the controller stops "
                "a running RTDE motion by itself when the connection drops)",
                device=self.config.host,
            )
        self._stop_requested.set()
        self._stop_now()
