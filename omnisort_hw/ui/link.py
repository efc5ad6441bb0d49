"""The interface's one way to the service: a status reader shared by every page, and each
command on a connection of its own.

One thread reads `status` every `period_s` whatever the number of browsers, so pages cost the
service nothing more as they multiply; a page reads the last snapshot. When the service cannot
be reached the snapshot says why, and the reader keeps trying until it comes back.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, TypeVar

from omnisort_hw.service.client import Client, ClientError, CommandError, ReplyError
from omnisort_hw.service.commands import Call, CellCommands, call_of
from omnisort_hw.service.states import JobRecord
from omnisort_hw.service.status_reply import StatusReply

__all__ = [
    "Call",
    "CellCommands",
    "ClientError",
    "CommandError",
    "Reader",
    "ReplyError",
    "Send",
    "ServiceLink",
    "Snapshot",
    "StartJob",
    "call_of",
]

R = TypeVar("R")
STATUS = call_of(CellCommands.status)


class Send(Protocol):
    """A page's way to send one quick command with its session's token: its typed reply, or
    None with the refusal shown on the page."""

    async def __call__(self, command: Call[R]) -> R | None: ...


StartJob = Callable[[Call[object]], bool]
"""A page's way to start a job: False, with why shown, when it was not sent."""


@dataclass(frozen=True)
class Snapshot:
    """The last reading of the service: its status, or why it could not be read."""

    status: StatusReply | None
    problem: str | None

    @property
    def reachable(self) -> bool:
        return self.status is not None


class Reader:
    """One connection kept for a reader that asks again and again (the status, the live
    view): opened at the first request, dropped after a failure of the connection and opened
    again at the next; a refusal by the service keeps it."""

    def __init__(self, connect: Callable[[], Client]) -> None:
        self._connect = connect
        self._client: Client | None = None

    def call(self, command: Call[R]) -> R:
        try:
            if self._client is None:
                self._client = self._connect()
            return command.send(self._client)
        except (ClientError, OSError, ValueError):
            self.close()
            raise

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None


class ServiceLink:
    """The service at host:port: `snapshot` (read by a thread every `period_s`), `call()`
    for one command on its own connection."""

    def __init__(
        self,
        host: str,
        port: int,
        period_s: float = 0.5,
        timeout_s: float = 5.0,
        connect_timeout_s: float = 2.0,
    ) -> None:
        self.host, self.port, self.period_s = host, port, period_s
        self.timeout_s, self.connect_timeout_s = timeout_s, connect_timeout_s
        self._snapshot = Snapshot(None, "not read yet")
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}"

    @property
    def snapshot(self) -> Snapshot:
        with self._lock:
            return self._snapshot

    def running_job(self) -> JobRecord | None:
        """The service's running job as last read (None: none, or the service unread)."""
        status = self.snapshot.status
        return status["job"] if status is not None else None

    def start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._read_loop, name="ui-status", daemon=True)
            self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=self.timeout_s + self.connect_timeout_s + 1.0)
            self._thread = None

    def _read_loop(self) -> None:
        reader = self.reader()
        while not self._stop.is_set():
            t0 = time.monotonic()
            try:
                snap = Snapshot(reader.call(STATUS), None)
            except (ClientError, CommandError, OSError, ValueError) as exc:
                snap = Snapshot(None, f"service unreachable at {self.address}: {exc}")
            with self._lock:
                self._snapshot = snap
            self._stop.wait(max(0.0, self.period_s - (time.monotonic() - t0)))
        reader.close()

    def reader(self) -> Reader:
        """A connection of its own, without a token, for a reader that asks again and again."""
        return Reader(lambda: self._client(None, self.timeout_s))

    def _client(self, token: str | None, timeout_s: float) -> Client:
        return Client(
            self.host,
            self.port,
            token=token,
            timeout_s=timeout_s,
            connect_timeout_s=self.connect_timeout_s,
        )

    def call(self, command: Call[R], token: str | None = None, timeout_s: float | None = None) -> R:
        """One command on a fresh connection: its typed reply, or CommandError (the service's
        typed error) or ClientError (unreachable, no reply in time, connection lost)."""
        with self._client(token, timeout_s if timeout_s is not None else self.timeout_s) as c:
            return command.send(c)
