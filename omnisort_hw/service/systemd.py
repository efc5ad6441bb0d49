"""sd_notify with the standard library: READY, WATCHDOG, STOPPING and STATUS over a datagram.

systemd passes `NOTIFY_SOCKET` (a filesystem path, or an abstract-namespace name starting with
'@') and, when `WatchdogSec=` is set, `WATCHDOG_USEC` (and `WATCHDOG_PID`). Outside systemd the
variables are absent and every call is a cheap no-op that returns False.
"""

from __future__ import annotations

import logging
import os
import socket
import threading
from collections.abc import Mapping

log = logging.getLogger(__name__)


def _address(raw: str) -> str | bytes | None:
    """The socket address for `NOTIFY_SOCKET`: '@name' is the abstract name '\\0name'."""
    if not raw:
        return None
    if raw.startswith("@"):
        return b"\0" + raw[1:].encode()
    if raw.startswith("/"):
        return raw
    return None


class Notifier:
    """Sends notifications to systemd's `NOTIFY_SOCKET`; a no-op when it is not set."""

    def __init__(self, environ: Mapping[str, str] | None = None) -> None:
        env = os.environ if environ is None else environ
        self._address = _address(env.get("NOTIFY_SOCKET", ""))
        self._lock = threading.Lock()
        self._sock: socket.socket | None = None
        self._watchdog_usec = 0
        usec = env.get("WATCHDOG_USEC", "")
        pid = env.get("WATCHDOG_PID", "")
        if usec.isdigit() and int(usec) > 0 and (not pid or pid == str(os.getpid())):
            self._watchdog_usec = int(usec)
        if self._address is not None:
            # Non-blocking: a receiver that stops reading must never stall the caller (the
            # event loop pings the watchdog); a full queue drops the message instead.
            self._sock = socket.socket(
                socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC | socket.SOCK_NONBLOCK
            )
        self._failures = 0

    @property
    def enabled(self) -> bool:
        """True when running under systemd with a notify socket."""
        return self._sock is not None

    @property
    def watchdog_interval_s(self) -> float | None:
        """How often to send WATCHDOG=1: half of `WATCHDOG_USEC`, None when there is no watchdog."""
        return self._watchdog_usec / 2e6 if self._watchdog_usec else None

    def notify(self, *fields: str) -> bool:
        """Send `KEY=VALUE` lines in one datagram; False when not under systemd or on failure."""
        if self._sock is None or self._address is None:
            return False
        message = "\n".join(_one_line(f) for f in fields).encode("utf-8", "replace")
        with self._lock:
            try:
                self._sock.sendto(message, self._address)
            except OSError as exc:
                self._failures += 1
                if self._failures in (1, 10, 100) or self._failures % 1000 == 0:
                    log.warning(
                        "sd_notify to %r failed (%d so far): %s", self._address, self._failures, exc
                    )
                return False
        return True

    def ready(self, status: str | None = None) -> bool:
        """READY=1 (and MAINPID): the devices are up and the port is listening."""
        extra = (f"STATUS={_one_line(status)}",) if status else ()
        return self.notify("READY=1", f"MAINPID={os.getpid()}", *extra)

    def watchdog(self) -> bool:
        """WATCHDOG=1: the main loop is alive (sent only when systemd set a watchdog)."""
        if not self._watchdog_usec:
            return False
        return self.notify("WATCHDOG=1")

    def stopping(self, status: str | None = None) -> bool:
        """STOPPING=1: the service is shutting down cleanly."""
        extra = (f"STATUS={_one_line(status)}",) if status else ()
        return self.notify("STOPPING=1", *extra)

    def status(self, text: str) -> bool:
        """STATUS=...: one line shown by `systemctl status`."""
        return self.notify(f"STATUS={_one_line(text)}")

    def close(self) -> None:
        with self._lock:
            if self._sock is not None:
                self._sock.close()
                self._sock = None


def _one_line(text: str) -> str:
    return " ".join(text.split())[:200]
