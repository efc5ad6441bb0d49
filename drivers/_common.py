"""Small helpers shared by the real drivers: config checks, OS error classification, back-off."""

from __future__ import annotations

import errno
import logging
import time
from dataclasses import dataclass

from drivers.errors import (
    DeviceBusyError,
    DeviceConfigError,
    DeviceDisconnectedError,
    DeviceError,
    DeviceNotFoundError,
)

log = logging.getLogger("drivers")


def require(condition: bool, section: str, key: str, message: str) -> None:
    """Raise `DeviceConfigError` naming `[section].key` unless `condition` holds."""
    if not condition:
        raise DeviceConfigError(f"[{section}].{key}: {message}", key=f"[{section}].{key}")


def classify_open_error(exc: BaseException, device: str, what: str) -> DeviceError:
    """Turn an OS-level failure to open `device` into the typed error a technician can act on."""
    code = getattr(exc, "errno", None)
    text = str(exc)
    if code == errno.ENOENT or "No such file" in text:
        return DeviceNotFoundError(
            f"{what} {device} does not exist: is it plugged in? (`omnisort devices list`)",
            device=device,
        )
    if code in (errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK) or "lock" in text.lower():
        return DeviceBusyError(
            f"{what} {device} is in use by another process (check with `fuser {device}`)",
            device=device,
        )
    if code in (errno.EACCES, errno.EPERM) or "Permission denied" in text:
        return DeviceError(
            f"no permission to open {what} {device}: add the service user to the group that "
            f"owns it (`ls -l {device}`, usually 'dialout' or 'video')",
            device=device,
        )
    return DeviceDisconnectedError(f"cannot open {what} {device}: {text}", device=device)


@dataclass
class Backoff:
    """Exponential back-off between reconnect attempts, with a cap and an attempt limit.

    `attempts = 0` means no limit. `ready()` tells whether the next attempt is due; `failed()`
    schedules the next one; `reset()` after a success.
    """

    initial_s: float
    max_s: float
    attempts: int
    count: int = 0
    next_time: float = 0.0

    def exhausted(self) -> bool:
        return self.attempts > 0 and self.count >= self.attempts

    def wait_s(self, now: float | None = None) -> float:
        """Seconds until the next attempt is due (0 when due now)."""
        return max(0.0, self.next_time - (time.monotonic() if now is None else now))

    def failed(self) -> float:
        """Record a failed attempt; return the delay until the next one."""
        self.count += 1
        delay = min(self.max_s, self.initial_s * (2 ** (self.count - 1)))
        self.next_time = time.monotonic() + delay
        return delay

    def reset(self) -> None:
        self.count = 0
        self.next_time = 0.0
