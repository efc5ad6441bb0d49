"""Typed device errors.

Every error a driver (real or simulated) raises on purpose derives from `DeviceError`. Each
class has a stable `code` (used by the CLI and the service protocol) and a message that names
the device (path, port or host) and says what a technician can check. `drivers` does not
depend on `omnisort_hw`; the CLI treats any exception with a string `code` the same way.
"""

from __future__ import annotations

from typing import Literal

SafetyStopKind = Literal["protective", "emergency"]


class DeviceError(Exception):
    """Base of every device error; `device` names the device (path, port, host) when known."""

    code: str = "device_error"

    def __init__(self, message: str, *, device: str | None = None) -> None:
        super().__init__(message)
        self.device = device


class DeviceTimeoutError(DeviceError):
    """The device did not answer or finish within its timeout."""

    code = "device_timeout"


class DeviceDisconnectedError(DeviceError):
    """The device was connected and went away (unplugged, server gone, connection dropped)."""

    code = "device_disconnected"


class DeviceNotFoundError(DeviceError):
    """The device is not there: no such path or port, nothing listening at the address."""

    code = "device_not_found"


class DeviceBusyError(DeviceError):
    """Another process holds the device (serial port locked, camera in use)."""

    code = "device_busy"


class BadReplyError(DeviceError):
    """The device answered something that is not in its protocol (garbage, wrong echo)."""

    code = "bad_device_reply"


class DeviceNotReadyError(DeviceError):
    """The device is there but not in a state to obey (arm powered off, brakes on, not remote)."""

    code = "device_not_ready"


class UnsupportedError(DeviceError):
    """The device has no such feature (e.g. a camera without manual exposure)."""

    code = "device_unsupported"


class SafetyStopError(DeviceError):
    """The arm is in a protective or emergency stop; it must be cleared at the robot."""

    code = "safety_stop"

    def __init__(self, message: str, *, kind: SafetyStopKind, device: str | None = None) -> None:
        super().__init__(message, device=device)
        self.kind: SafetyStopKind = kind


class DeviceConfigError(DeviceError):
    """A device setting is wrong or missing; `key` names it, e.g. `[laser].port`."""

    code = "bad_device_config"

    def __init__(self, message: str, *, key: str, device: str | None = None) -> None:
        super().__init__(message, device=device)
        self.key = key


class MotionLimitError(DeviceError):
    """A target is outside the workspace box or the joint limits; nothing was sent to the arm."""

    code = "motion_refused"


__all__ = [
    "BadReplyError",
    "DeviceBusyError",
    "DeviceConfigError",
    "DeviceDisconnectedError",
    "DeviceError",
    "DeviceNotFoundError",
    "DeviceNotReadyError",
    "DeviceTimeoutError",
    "MotionLimitError",
    "SafetyStopError",
    "SafetyStopKind",
    "UnsupportedError",
]
