"""The only module that talks to ur-rtde (`rtde_control`, `rtde_receive`, `rtde_io`).

`URLink` is the boundary the `URArm` driver is written against: SI units as the controller uses
them (radians, metres, rotation vectors in radians), raw robot and safety mode numbers, and typed
`DeviceError`s instead of ur-rtde's `RuntimeError`s. `RTDELink` implements it with ur-rtde.
No controller (or URSim) can run where the tests run, so everything above this boundary is
tested against a recording stand-in that implements `URLink` (`tests/drivers/ur_standin.py`);
this file is kept as thin as possible and is exercised only up to the network probe.
"""

from __future__ import annotations

import socket
import struct
from collections.abc import Callable
from typing import Any, Literal, Protocol, TypeVar

from drivers._common import StillRunningError, call_with_timeout
from drivers.errors import (
    BadReplyError,
    DeviceDisconnectedError,
    DeviceError,
    DeviceNotFoundError,
    DeviceTimeoutError,
)

IOKind = Literal["tool", "standard", "configurable"]
RTDE_PORT = 30004
_RTDE_REQUEST_PROTOCOL_VERSION = 86  # 'V'
T = TypeVar("T")

# Bit offsets of each output/input group in actual_digital_{output,input}_bits.
_IO_BIT_OFFSET = {"standard": 0, "configurable": 8, "tool": 16}


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


def _with_timeout(fn: Callable[[], T], timeout_s: float, what: str, host: str) -> T:
    """Run a blocking ur-rtde call in a helper thread; raise `DeviceTimeoutError` after timeout.

    This bounds the wait only if the call releases the GIL; ur-rtde's constructors do not,
    which is why `probe_rtde` runs first.
    """
    try:
        return call_with_timeout(fn, timeout_s, f"ur-{what}")
    except StillRunningError:
        raise DeviceTimeoutError(
            f"UR controller at {host}: {what} did not finish within {timeout_s:.1f} s",
            device=host,
        ) from None


class RTDELink:
    """`URLink` over ur-rtde. Imports ur-rtde on `open()` only."""

    def __init__(self) -> None:
        self.host = ""
        self._rcv: Any = None
        self._ctl: Any = None
        self._io: Any = None

    def _fail(self, what: str, exc: BaseException) -> DeviceError:
        if self._rcv is not None and not self._rcv.isConnected():
            return DeviceDisconnectedError(
                f"UR controller at {self.host}: connection lost during {what} ({exc})",
                device=self.host,
            )
        return DeviceError(f"UR controller at {self.host}: {what} failed: {exc}", device=self.host)

    def _call(self, what: str, fn: Callable[[], T]) -> T:
        if self._rcv is None:
            raise DeviceDisconnectedError(
                f"UR controller at {self.host or '?'} is not connected", device=self.host
            )
        try:
            return fn()
        except RuntimeError as exc:
            raise self._fail(what, exc) from exc

    def open(self, host: str, timeout_s: float) -> None:
        self.host = host
        probe_rtde(host, min(timeout_s, 2.0))
        import rtde_control
        import rtde_io
        import rtde_receive

        def build() -> tuple[Any, Any, Any]:
            rcv = rtde_receive.RTDEReceiveInterface(host)
            ctl = rtde_control.RTDEControlInterface(host)
            io = rtde_io.RTDEIOInterface(host)
            return rcv, ctl, io

        try:
            self._rcv, self._ctl, self._io = _with_timeout(build, timeout_s, "connect", host)
        except RuntimeError as exc:
            raise DeviceError(
                f"UR controller at {host} refused the RTDE connection ({exc}): put the robot in "
                "Remote Control mode and make sure no other program holds the RTDE control "
                "interface",
                device=host,
            ) from exc

    def close(self) -> None:
        for iface in (self._ctl, self._io, self._rcv):
            if iface is not None:
                try:
                    if hasattr(iface, "stopScript"):
                        iface.stopScript()
                    iface.disconnect()
                except RuntimeError:
                    pass
        self._rcv = self._ctl = self._io = None

    def is_connected(self) -> bool:
        return all(i is not None and i.isConnected() for i in (self._rcv, self._ctl, self._io))

    def reconnect(self, timeout_s: float) -> None:
        if self._rcv is None:
            raise DeviceDisconnectedError(
                f"UR controller at {self.host or '?'} was never connected", device=self.host
            )
        probe_rtde(self.host, min(timeout_s, 2.0))

        def again() -> bool:
            return bool(self._rcv.reconnect() and self._ctl.reconnect() and self._io.reconnect())

        if not _with_timeout(again, timeout_s, "reconnect", self.host):
            raise DeviceDisconnectedError(
                f"UR controller at {self.host}: reconnect failed", device=self.host
            )

    def actual_q(self) -> list[float]:
        return list(self._call("getActualQ", lambda: self._rcv.getActualQ()))

    def actual_tcp_pose(self) -> list[float]:
        return list(self._call("getActualTCPPose", lambda: self._rcv.getActualTCPPose()))

    def robot_mode(self) -> int:
        return int(self._call("getRobotMode", lambda: self._rcv.getRobotMode()))

    def safety_mode(self) -> int:
        return int(self._call("getSafetyMode", lambda: self._rcv.getSafetyMode()))

    def move_j(self, q: list[float], speed: float, accel: float) -> None:
        if not self._call("moveJ", lambda: self._ctl.moveJ(q, speed, accel, True)):
            raise DeviceError(f"UR controller at {self.host} rejected moveJ", device=self.host)

    def move_l(self, pose: list[float], speed: float, accel: float) -> None:
        if not self._call("moveL", lambda: self._ctl.moveL(pose, speed, accel, True)):
            raise DeviceError(f"UR controller at {self.host} rejected moveL", device=self.host)

    def is_moving(self) -> bool:
        status = self._call(
            "getAsyncOperationProgressEx", lambda: self._ctl.getAsyncOperationProgressEx()
        )
        return bool(status.isAsyncOperationRunning())

    def stop_j(self, decel: float) -> None:
        self._call("stopJ", lambda: self._ctl.stopJ(decel))

    def stop_l(self, decel: float) -> None:
        self._call("stopL", lambda: self._ctl.stopL(decel))

    def set_output(self, kind: IOKind, pin: int, value: bool) -> None:
        method = {
            "tool": "setToolDigitalOut",
            "standard": "setStandardDigitalOut",
            "configurable": "setConfigurableDigitalOut",
        }[kind]
        if not self._call(
            f"set {kind} output {pin}", lambda: getattr(self._io, method)(pin, value)
        ):
            raise DeviceError(
                f"UR controller at {self.host} rejected setting {kind} output {pin}",
                device=self.host,
            )

    def output(self, kind: IOKind, pin: int) -> bool:
        bits = int(
            self._call("getActualDigitalOutputBits", lambda: self._rcv.getActualDigitalOutputBits())
        )
        return bool((bits >> (_IO_BIT_OFFSET[kind] + pin)) & 1)

    def input(self, kind: IOKind, pin: int) -> bool:
        bits = int(
            self._call("getActualDigitalInputBits", lambda: self._rcv.getActualDigitalInputBits())
        )
        return bool((bits >> (_IO_BIT_OFFSET[kind] + pin)) & 1)
