"""Small helpers shared by the real drivers: config checks, OS error classification, back-off,
bounded waits on blocking library calls."""

from __future__ import annotations

import errno
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

from drivers.errors import (
    DeviceBusyError,
    DeviceConfigError,
    DeviceDisconnectedError,
    DeviceError,
    DeviceNotFoundError,
)

log = logging.getLogger("drivers")

T = TypeVar("T")


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


class StillRunningError(Exception):
    """`call_with_timeout`: the call had not returned in time; `worker` is its thread."""

    def __init__(self, worker: threading.Thread) -> None:
        super().__init__(f"{worker.name} still running")
        self.worker = worker


def call_with_timeout(fn: Callable[[], T], timeout_s: float, thread_name: str) -> T:
    """Run a blocking library call in a daemon helper thread and wait at most `timeout_s`.

    Returns its value or re-raises its exception; raises `StillRunningError` (carrying the thread,
    which is left to finish) when it has not returned, so the caller raises its own typed
    timeout. This bounds the wait only if the call releases the GIL.
    """
    value: list[T] = []
    error: list[BaseException] = []

    def run() -> None:
        try:
            value.append(fn())
        except BaseException as exc:
            error.append(exc)

    worker = threading.Thread(target=run, name=thread_name, daemon=True)
    worker.start()
    worker.join(timeout_s)
    if worker.is_alive():
        raise StillRunningError(worker)
    if error:
        raise error[0]
    return value[0]
