"""The client of a virtual cell's control channel: one JSON object per line out, one per line
back, each request bounded by a timeout. The Simulator tab and the test harness
(`sim_backend.virtual_cell.launcher`) speak it; the service never does, so it never learns
that its cell is simulated. It imports nothing of the simulator: the channel's commands are
declared in `sim_requests` (docs/virtual_cell.md lists them), and `send` sends a command's
request record and reads its reply as the record the command declares."""

from __future__ import annotations

import contextlib
import json
import socket
import threading
from typing import Any

from omnisort_hw.request_fields import wire_args
from omnisort_hw.sim_requests import SIM_COMMANDS, command_of
from omnisort_hw.wire_records import WireError, from_wire

DEFAULT_TIMEOUT_S = 10.0
MOVE_TIMEOUT_S = 120.0  # a change the reply waits to see in a picture, or the arm to stand


class SimControlError(Exception):
    """The control channel at `address` refused a request (its reason) or cannot be reached."""

    def __init__(self, address: str, message: str) -> None:
        super().__init__(f"{address}: {message}")
        self.address, self.message = address, message


class SimLink:
    """One connection to the control channel at host:port, opened on first use and again after
    a failure; requests are serialised (one line in flight)."""

    def __init__(self, host: str, port: int) -> None:
        self.host, self.port = host, port
        self.address = f"{host}:{port}"
        self._sock: socket.socket | None = None
        self._rfile: Any = None
        self._lock = threading.Lock()

    def control(
        self, cmd: str, timeout_s: float = DEFAULT_TIMEOUT_S, **args: Any
    ) -> dict[str, Any]:
        """Send `{"cmd": cmd, **args}`; the reply's result, checked against the reply record
        its command declares (`sim_requests.SIM_COMMANDS`); SimControlError otherwise."""
        return self._exchange(cmd, timeout_s, args)[0]

    def send(self, request: Any, timeout_s: float = DEFAULT_TIMEOUT_S) -> object:
        """The command a request record is declared for (`sim_requests.command_of`), sent with
        its arguments; its reply read as the record the command declares. No caller names a
        command by a string, nor reads a reply by a key."""
        return self._exchange(command_of(request), timeout_s, wire_args(request))[1]

    def _exchange(
        self, cmd: str, timeout_s: float, args: dict[str, Any]
    ) -> tuple[dict[str, Any], object]:
        """One request: the reply's result, and the same read as its command's record (read
        once, which checks it)."""
        with self._lock:
            try:
                if self._sock is None:
                    self._sock = socket.create_connection((self.host, self.port), timeout_s)
                    self._rfile = self._sock.makefile("rb")
                self._sock.settimeout(timeout_s)
                self._sock.sendall(json.dumps({"cmd": cmd, **args}).encode() + b"\n")
                line = self._rfile.readline()
            except OSError as exc:
                self._drop()
                raise SimControlError(self.address, f"control channel: {exc}") from exc
            if not line:
                self._drop()
                raise SimControlError(self.address, "control channel closed")
        try:
            reply = json.loads(line)
        except ValueError as exc:
            raise SimControlError(self.address, f"not a control-channel reply: {exc}") from exc
        if not reply.get("ok"):
            raise SimControlError(self.address, str(reply.get("error")))
        result = dict(reply.get("result") or {})
        spec = SIM_COMMANDS.get(cmd)
        if spec is None:  # a command this side does not declare: its result as it came
            return result, result
        try:  # the reply its command declares (a cell of another version?)
            return result, from_wire(spec.reply, result)
        except WireError as exc:
            raise SimControlError(self.address, f"{cmd}: the reply does not fit {exc}") from None

    def _drop(self) -> None:
        for closing in (self._rfile, self._sock):
            if closing is not None:
                with contextlib.suppress(OSError):
                    closing.close()
        self._sock = self._rfile = None

    def close(self) -> None:
        with self._lock:
            self._drop()
