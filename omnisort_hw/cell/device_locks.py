"""The devices' locks: one command at a time on the camera and on the laser, a typed refusal
when a device stays busy, and live pictures that give way to the commands.

A screen asks for a live picture every half second or so (`Cell.live_frame`, `view`, `detect`)
and a picture holds the camera until its fresh frame arrives. A command (a capture, a sort's
measurement) must never be kept from the camera by them: `CameraLock.held` counts the commands
waiting for it, and `CameraLock.for_screen` refuses a picture at once while one waits, so the
waiting command takes the camera as soon as the picture being grabbed is done.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

from omnisort_hw.errors import OmnisortError

DEVICE_LOCK_TIMEOUT_S = 5.0
VIEW_LOCK_TIMEOUT_S = 0.5  # a live picture does not wait for a measurement to end
VIEW_GRAB_TIMEOUT_S = 2.0
"""How long a live picture waits for its fresh frame, holding the camera: a stream sends one
every tenth of a second, or after a render (1.5 s at 960 px on the virtual cell, whose camera
sends nothing while the arm moves); a command waits 5 s for the camera, so a screen asking
every half second never makes it give up (it did, with the read timeout's 30 s)."""


class DeviceLockTimeoutError(OmnisortError):
    """A device stayed busy with another command for longer than the lock timeout."""

    code = "busy"


@contextmanager
def locked(
    lock: threading.Lock, what: str, timeout_s: float = DEVICE_LOCK_TIMEOUT_S
) -> Iterator[None]:
    """`lock` held for a command, or DeviceLockTimeoutError naming `what` after timeout_s."""
    if not lock.acquire(timeout=timeout_s):
        raise DeviceLockTimeoutError(
            f"the {what} has been busy with another command for {timeout_s:g} s"
        )
    try:
        yield
    finally:
        lock.release()


class CameraLock:
    """The camera's lock, with the commands first (see the module doc)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._count = threading.Lock()
        self._wanted = 0  # commands waiting for the camera

    @contextmanager
    def held(self, timeout_s: float = DEVICE_LOCK_TIMEOUT_S) -> Iterator[None]:
        """The camera for a command: live pictures give way while it waits."""
        with self._count:
            self._wanted += 1
        try:
            acquired = self._lock.acquire(timeout=timeout_s)
        finally:
            with self._count:
                self._wanted -= 1
        if not acquired:
            raise DeviceLockTimeoutError(
                f"the camera has been busy with another command for {timeout_s:g} s"
            )
        try:
            yield
        finally:
            self._lock.release()

    @contextmanager
    def for_screen(self, timeout_s: float = VIEW_LOCK_TIMEOUT_S) -> Iterator[None]:
        """The camera for a live picture: refused at once while a command waits for it, and
        after `timeout_s` while one holds it."""
        with self._count:
            wanted = self._wanted
        if wanted or not self._lock.acquire(timeout=timeout_s):
            raise DeviceLockTimeoutError("the camera is busy with a measurement: no live picture")
        try:
            yield
        finally:
            self._lock.release()
