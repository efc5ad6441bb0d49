"""The client of a virtual cell's control channel: one JSON object per line out, one per line
back, each request bounded by a timeout. The Simulator tab and the test harness
(`sim_backend.virtual_cell.launcher`) speak it; the service never does, so it never learns
that its cell is simulated. It imports nothing of the simulator: the channel's commands are
declared in `sim_requests` (docs/virtual_cell.md lists them), and each has one method here that
sends its request record through `execute`."""

from __future__ import annotations

import contextlib
import json
import socket
import threading
from typing import Any

from omnisort_hw import sim_requests as sr
from omnisort_hw.request_fields import wire_args

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
        """Send `{"cmd": cmd, **args}`; the reply's result (SimControlError otherwise)."""
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
        return dict(reply.get("result") or {})

    def _drop(self) -> None:
        for closing in (self._rfile, self._sock):
            if closing is not None:
                with contextlib.suppress(OSError):
                    closing.close()
        self._sock = self._rfile = None

    def close(self) -> None:
        with self._lock:
            self._drop()

    # -- one method per command, each through `execute` ------------------------------------

    def execute(
        self, cmd: str, request: Any = None, timeout_s: float = DEFAULT_TIMEOUT_S
    ) -> dict[str, Any]:
        """The command `cmd` with its request record's arguments (none: its defaults)."""
        return self.control(cmd, timeout_s, **wire_args(request))

    def describe(self) -> dict[str, Any]:
        return self.execute("describe")

    def schema(self, cmd: str) -> dict[str, Any]:
        """The JSON Schema of `cmd`'s arguments, as the channel describes it."""
        return dict(self.describe()["commands"][cmd]["args"])

    def status(self) -> dict[str, Any]:
        return self.execute("status")

    def truth(self, timeout_s: float = DEFAULT_TIMEOUT_S) -> dict[str, Any]:
        return self.execute("truth", timeout_s=timeout_s)

    def board(self, request: sr.BoardRequest) -> dict[str, Any]:
        return self.execute("board", request, MOVE_TIMEOUT_S)

    def camera(self, request: sr.CameraRequest) -> dict[str, Any]:
        return self.execute("camera", request, MOVE_TIMEOUT_S)

    def knock(self, request: sr.KnockRequest) -> dict[str, Any]:
        return self.execute("knock", request, MOVE_TIMEOUT_S)

    def laser(self, request: sr.LaserRequest) -> dict[str, Any]:
        return self.execute("laser", request, MOVE_TIMEOUT_S)

    def target(self, request: sr.TargetRequest) -> dict[str, Any]:
        return self.execute("target", request, MOVE_TIMEOUT_S)

    def cube(self, request: sr.CubeRequest) -> dict[str, Any]:
        return self.execute("cube", request, MOVE_TIMEOUT_S)

    def joints(self, request: sr.JointsRequest) -> dict[str, Any]:
        return self.execute("joints", request, MOVE_TIMEOUT_S)

    def move_to(self, request: sr.MoveToRequest) -> dict[str, Any]:
        return self.execute("move_to", request, MOVE_TIMEOUT_S)

    def gripper(self, request: sr.GripperRequest) -> dict[str, Any]:
        return self.execute("gripper", request, MOVE_TIMEOUT_S)

    def render(self, request: sr.RenderRequest) -> dict[str, Any]:
        return self.execute("render", request, MOVE_TIMEOUT_S)

    def drop(self, request: sr.DropRequest) -> dict[str, Any]:
        return self.execute("drop", request)

    def stall(self, request: sr.StallRequest) -> dict[str, Any]:
        return self.execute("stall", request)

    def unstall(self, request: sr.UnstallRequest) -> dict[str, Any]:
        return self.execute("unstall", request)

    def protective_stop(self) -> dict[str, Any]:
        return self.execute("protective_stop")

    def emergency_stop(self) -> dict[str, Any]:
        return self.execute("emergency_stop")

    def release_emergency_stop(self) -> dict[str, Any]:
        return self.execute("release_emergency_stop")
