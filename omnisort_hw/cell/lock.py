"""One service per cell: an exclusive lock on `STATE_DIR/omnisort.lock`, taken before any
device is opened, holding the PID of its owner.

The lock is an advisory `flock` on an open descriptor, so the kernel drops it when the holder
exits, however it exits (SIGKILL included): a stale file never blocks a restart. The PID is
written in one `write` after the lock is taken; it is informative only (for the message).
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from omnisort_hw.errors import OmnisortError

LOCK_NAME = "omnisort.lock"


class InstanceLockedError(OmnisortError):
    """Another service already runs this cell (same state directory)."""

    code = "instance_locked"


class InstanceLock:
    """`with InstanceLock(state_dir):` holds the cell for this process."""

    def __init__(self, state_dir: str | os.PathLike[str]) -> None:
        self.path = Path(state_dir) / LOCK_NAME
        self._fd: int | None = None

    def holder_pid(self) -> int | None:
        """The PID written by the current holder (None when unknown)."""
        try:
            text = self.path.read_text().strip()
        except OSError:
            return None
        return int(text) if text.isdigit() else None

    def acquire(self) -> InstanceLock:
        """Take the lock or raise InstanceLockedError naming the holder's PID."""
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            pid = self.holder_pid()
            who = f"PID {pid}" if pid is not None else "a process whose PID is not recorded"
            raise InstanceLockedError(
                f"{self.path}: this cell is already run by another omnisort service ({who}); "
                "stop it first (systemctl stop omnisort) or give this one its own state_dir"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        """Give the lock up (the file stays; an unlocked file means nobody holds the cell)."""
        if self._fd is not None:
            os.ftruncate(self._fd, 0)
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> InstanceLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()
