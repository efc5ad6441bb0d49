"""The only module that talks to ur-rtde (`rtde_control`, `rtde_receive`, `rtde_io`).

`URLink` is the boundary the `URArm` driver is written against: SI units as the controller uses
them (radians, metres, rotation vectors in radians), raw robot and safety mode numbers, and typed
`DeviceError`s instead of ur-rtde's `RuntimeError`s. `RTDELink` implements it with ur-rtde,
run in a worker process (`drivers.ur_rtde_worker`) so that no ur-rtde call can block this one.
The unit tests run `URArm` against a recording stand-in (`tests/drivers/ur_standin.py`); the
virtual cell (`omnisort sim virtual-cell`) runs this link, and ur-rtde itself, end to end.
"""

from __future__ import annotations

import socket
import struct
from typing import Any, Literal, Protocol

from drivers.errors import (
    BadReplyError,
    DeviceDisconnectedError,
    DeviceError,
    DeviceNotFoundError,
    DeviceTimeoutError,
)
from drivers.ur_rtde_worker import SAFETY_MODE_NORMAL, RTDEWorker

IOKind = Literal["tool", "standard", "configurable"]
RTDE_PORT = 30004
_RTDE_REQUEST_PROTOCOL_VERSION = 86  # 'V'


class URLink(Protocol):
    """What `URArm` needs from a UR controller, in the controller's own units."""

    def open(self, host: str, timeout_s: float) -> None:
        """Connect the receive, control and IO interfaces; typed errors on failure."""

    def close(self) -> None:
        """Disconnect; safe to call repeatedly."""

    def is_connected(self) -> bool:
        """True while every interface is connected."""

    def reconnect(self, timeout_s: float) -> None:
        """Re-establish a dropped connection (never resumes a motion)."""

    def actual_q(self) -> list[float]:
        """Joint positions, rad."""

    def actual_qd(self) -> list[float]:
        """Joint speeds, rad/s (from the same state stream as `actual_q`)."""

    def actual_tcp_pose(self) -> list[float]:
        """TCP pose [x, y, z m, rx, ry, rz rad rotation vector] in the base frame."""

    def robot_mode(self) -> int:
        """RTDE robot_mode (7 = RUNNING)."""

    def safety_mode(self) -> int:
        """RTDE safety_mode (1 = NORMAL, 3 = PROTECTIVE_STOP, 7 = ROBOT_EMERGENCY_STOP...)."""

    def move_j(self, q: list[float], speed: float, accel: float) -> None:
        """Start an asynchronous joint move (rad, rad/s, rad/s^2); returns once accepted."""

    def move_l(self, pose: list[float], speed: float, accel: float) -> None:
        """Start an asynchronous linear move (m + rotvec rad, m/s, m/s^2)."""

    def move_path(self, rows: list[tuple[str, list[float]]]) -> None:
        """Start an asynchronous blended path: ("joint" | "linear", [q rad or pose m + rotvec,
        speed, accel, blend m]) rows, as ur-rtde's moveJ/moveL path rows."""

    def is_moving(self) -> bool:
        """True while an asynchronous move is running."""

    def stop_j(self, decel: float) -> None:
        """Decelerate joints to zero (rad/s^2)."""

    def stop_l(self, decel: float) -> None:
        """Decelerate the TCP to zero (m/s^2)."""

    def set_output(self, kind: IOKind, pin: int, value: bool) -> None:
        """Set a digital output."""

    def output(self, kind: IOKind, pin: int) -> bool:
        """Read back a digital output."""

    def input(self, kind: IOKind, pin: int) -> bool:
        """Read a digital input."""


def probe_rtde(host: str, timeout_s: float, port: int = RTDE_PORT) -> None:
    """Check within `timeout_s` that an RTDE server answers at host:port, before ur-rtde is used.

    ur-rtde's constructors block without a timeout and hold the GIL while they wait, so a helper
    thread cannot bound them. This probe speaks the first RTDE message itself (request protocol
    version 2, type 'V') with a socket timeout, so a wrong address, a closed port or a peer that
    is not an RTDE server becomes a typed error instead of a hang.
    """
    try:
        with socket.create_connection((host, port), timeout=timeout_s) as sock:
            sock.settimeout(timeout_s)
            sock.sendall(struct.pack(">HBH", 5, _RTDE_REQUEST_PROTOCOL_VERSION, 2))
            reply = b""
            while len(reply) < 4:
                chunk = sock.recv(4 - len(reply))
                if not chunk:
                    break
                reply += chunk
    except TimeoutError as exc:
        raise DeviceTimeoutError(
            f"no RTDE answer from {host}:{port} within {timeout_s:.1f} s: check [arm].host, the "
            "network cable and that the controller is switched on and booted",
            device=host,
        ) from exc
    except OSError as exc:
        raise DeviceNotFoundError(
            f"cannot reach a UR controller at {host}:{port} ({exc.strerror or exc}): check "
            "[arm].host and that the controller is booted",
            device=host,
        ) from exc
    if len(reply) < 4 or reply[2] != _RTDE_REQUEST_PROTOCOL_VERSION:
        raise BadReplyError(
            f"{host}:{port} is not a UR RTDE server (answered {reply!r}): check [arm].host",
            device=host,
        )


class RTDELink:
    """`URLink` over ur-rtde, which runs in a worker process (`drivers.ur_rtde_worker`): every
    call waits at most `call_timeout_s`, a stalled controller gives `DeviceTimeoutError`, a
    vanished one `DeviceDisconnectedError`, and no ur-rtde call can hang this process."""

    def __init__(self, call_timeout_s: float = 2.0, state_timeout_s: float = 0.5) -> None:
        self.host = ""
        self.call_timeout_s = call_timeout_s
        self.state_timeout_s = state_timeout_s
        self._worker: RTDEWorker | None = None

    def _call(self, name: str, *args: Any) -> Any:
        if self._worker is None:
            raise DeviceDisconnectedError(
                f"UR controller at {self.host or '?'} is not connected", device=self.host
            )
        try:
            return self._worker.call(name, *args, timeout_s=self.call_timeout_s)
        except DeviceDisconnectedError:
            # ur-rtde's own reconnect lost a command under it: a fresh worker (fresh
            # interfaces) on the next reconnect instead of trusting that one to recover
            self._worker.kill()
            raise

    def open(self, host: str, timeout_s: float) -> None:
        self.host = host
        probe_rtde(host, min(timeout_s, 2.0))
        worker = RTDEWorker(host, self.state_timeout_s)
        worker.start(timeout_s)
        self._worker = worker

    def close(self) -> None:
        worker, self._worker = self._worker, None
        if worker is not None:
            worker.close(self.call_timeout_s)

    def is_connected(self) -> bool:
        if self._worker is None or not self._worker.alive:
            return False
        try:
            return bool(self._call("is_connected"))
        except DeviceError:
            return False

    def reconnect(self, timeout_s: float) -> None:
        """A fresh worker and fresh connections; no motion is resent."""
        if not self.host:
            raise DeviceDisconnectedError("UR controller was never connected", device=self.host)
        if self._worker is not None:
            self._worker.kill()
            self._worker = None
        self.open(self.host, timeout_s)

    def actual_q(self) -> list[float]:
        return list(self._call("actual_q"))

    def actual_qd(self) -> list[float]:
        return list(self._call("actual_qd"))

    def actual_tcp_pose(self) -> list[float]:
        return list(self._call("actual_tcp_pose"))

    def robot_mode(self) -> int:
        return int(self._call("modes")[0])

    def safety_mode(self) -> int:
        return int(self._call("modes")[1])

    def move_j(self, q: list[float], speed: float, accel: float) -> None:
        if not self._call("move_j", q, speed, accel):
            raise self._rejected("moveJ")

    def move_l(self, pose: list[float], speed: float, accel: float) -> None:
        if not self._call("move_l", pose, speed, accel):
            raise self._rejected("moveL")

    def move_path(self, rows: list[tuple[str, list[float]]]) -> None:
        if not self._call("move_path", rows):
            raise self._rejected("movePath")

    def _rejected(self, what: str) -> DeviceError:
        robot, safety = self._call("modes")
        if safety != SAFETY_MODE_NORMAL:
            from drivers.errors import SafetyStopError, SafetyStopKind

            kind: SafetyStopKind = "emergency" if safety in (6, 7) else "protective"
            return SafetyStopError(
                f"UR controller at {self.host} rejected {what}: safety mode {safety}",
                kind=kind,
                device=self.host,
            )
        return DeviceError(
            f"UR controller at {self.host} rejected {what} (robot mode {robot})", device=self.host
        )

    def is_moving(self) -> bool:
        return bool(self._call("is_moving"))

    def stop_j(self, decel: float) -> None:
        self._call("stop_j", decel)

    def stop_l(self, decel: float) -> None:
        self._call("stop_l", decel)

    def set_output(self, kind: IOKind, pin: int, value: bool) -> None:
        if not self._call("set_output", kind, pin, value):
            raise DeviceError(
                f"UR controller at {self.host} rejected setting {kind} output {pin}",
                device=self.host,
            )

    def output(self, kind: IOKind, pin: int) -> bool:
        return bool(self._call("output", kind, pin))

    def input(self, kind: IOKind, pin: int) -> bool:
        return bool(self._call("input", kind, pin))
