"""A small blocking client of the control protocol (used by `omnisort ctl`, the demo, tests,
benchmarks and the operator interface).

`call()` returns a reply as it came (`omnisort ctl` prints it); `execute()` returns its result
or raises `CommandError`, and the typed methods (`status()`, `map(MapRequest(...))`, ...) of
`commands.CellCommands` are built on it. Every call has a timeout: connecting, sending and
waiting for the reply.
"""

from __future__ import annotations

import itertools
import json
import socket
import time
from collections.abc import Callable
from typing import Any

from omnisort_hw.config.service import DEFAULT_PORT
from omnisort_hw.service.commands import CellCommands, ClientError, CommandError, ReplyError

MAX_REPLY_BYTES = 256 * 1024 * 1024
__all__ = ["Client", "ClientError", "CommandError", "ReplyError"]


class Client(CellCommands):
    """One TCP connection; `call()` sends a request and returns its reply as a dict,
    `execute()` its result, and one method per command its result too."""

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        token: str | None = None,
        timeout_s: float = 10.0,
        connect_timeout_s: float = 5.0,
        source_host: str | None = None,
    ) -> None:
        """`source_host`: the local address to connect from (a test or benchmark standing in for
        several hosts uses addresses of 127.0.0.0/8)."""
        self.host, self.port, self.token, self.timeout_s = host, port, token, timeout_s
        source = (source_host, 0) if source_host is not None else None
        try:
            self._sock = socket.create_connection(
                (host, port), timeout=connect_timeout_s, source_address=source
            )
        except OSError as exc:
            raise ClientError(f"cannot connect to {host}:{port}: {exc}") from None
        self._sock.settimeout(timeout_s)
        self._buf = bytearray()
        self._ids = itertools.count(1)

    def send_raw(self, data: bytes) -> None:
        """Send bytes as they are (tests send malformed lines with this)."""
        try:
            self._sock.sendall(data)
        except OSError as exc:
            raise ClientError(f"send to {self.host}:{self.port} failed: {exc}") from None

    def read_reply(self, timeout_s: float | None = None) -> dict[str, Any]:
        """The next reply line as a dict."""
        self._sock.settimeout(timeout_s if timeout_s is not None else self.timeout_s)
        while True:
            nl = self._buf.find(b"\n")
            if nl >= 0:
                line = bytes(self._buf[:nl])
                del self._buf[: nl + 1]
                return json.loads(line)
            if len(self._buf) > MAX_REPLY_BYTES:
                raise ClientError("reply larger than the client accepts")
            try:
                chunk = self._sock.recv(1 << 16)
            except TimeoutError:
                raise ClientError(
                    f"no reply from {self.host}:{self.port} within {self._sock.gettimeout()} s"
                ) from None
            except OSError as exc:
                raise ClientError(f"receive from {self.host}:{self.port} failed: {exc}") from None
            if not chunk:
                raise ClientError(f"{self.host}:{self.port} closed the connection")
            self._buf += chunk

    def send(self, cmd: str, args: dict[str, Any] | None = None, **extra: Any) -> int:
        """Send one request without waiting; returns its id."""
        rid = next(self._ids)
        req: dict[str, Any] = {"id": rid, "cmd": cmd}
        if args:
            req["args"] = args
        token = extra.pop("token", self.token)
        if token is not None:
            req["token"] = token
        req.update(extra)
        self.send_raw(json.dumps(req).encode() + b"\n")
        return rid

    def call(
        self,
        cmd: str,
        args: dict[str, Any] | None = None,
        timeout_s: float | None = None,
        on_event: Callable[[dict[str, Any]], None] | None = None,
    ) -> dict[str, Any]:
        """Send a request and wait for the reply with the same id (others are skipped).
        With `on_event`, the request asks for a job's progress events and each is passed to
        it as it arrives; the timeout still bounds the whole wait for the reply."""
        rid = self.send(cmd, args, progress=True) if on_event else self.send(cmd, args)
        limit = timeout_s if timeout_s is not None else self.timeout_s
        deadline = time.monotonic() + limit
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise ClientError(f"no reply from {self.host}:{self.port} within {limit} s")
            reply = self.read_reply(left)
            if reply.get("id") != rid:
                continue
            if "event" in reply and "ok" not in reply:
                if on_event is not None:
                    on_event(reply.get("progress", {}))
                continue
            return reply

    def execute(
        self,
        cmd: str,
        args: dict[str, Any] | None = None,
        on_event: Callable[[dict[str, Any]], None] | None = None,
        timeout_s: float | None = None,
    ) -> dict[str, Any]:
        """The command's result; CommandError when the service answers with an error."""
        reply = self.call(cmd, args or None, timeout_s, on_event)
        if not reply.get("ok"):
            raise CommandError(cmd, dict(reply.get("error") or {}))
        return dict(reply.get("result") or {})

    def close(self) -> None:
        self._sock.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
