"""The UR controller's TCP faces over `URController`: RTDE (30004), dashboard (29999) and the
script port (30003), plus the fault switches the control channel flips (drop, stall).

One thread per connection; every socket read has a timeout so a stop request is seen within
`POLL_S`. A stalled face keeps its connections open and answers nothing until the stall ends,
like a controller whose network stack hangs; a dropped face closes every open connection once.
"""

from __future__ import annotations

import contextlib
import logging
import re
import socket
import struct
import threading
import time
from collections.abc import Callable
from typing import Any

from sim_backend.virtual_cell import rtde_wire as wire
from sim_backend.virtual_cell.controller import (
    ROBOT_MODE_NAMES,
    SAFETY_MODE_NAMES,
    URController,
)

log = logging.getLogger("virtual_cell.servers")

RTDE_PORT, DASHBOARD_PORT, SCRIPT_PORT = 30004, 29999, 30003
POLL_S = 0.2


class Faults:
    """Stall deadlines per face ("arm", "dashboard", "laser", "camera"); monotonic seconds."""

    def __init__(self) -> None:
        self._until: dict[str, float] = {}

    def stall(self, face: str, seconds: float) -> None:
        self._until[face] = time.monotonic() + seconds

    def clear(self, face: str) -> None:
        self._until.pop(face, None)

    def stalled(self, face: str) -> bool:
        return time.monotonic() < self._until.get(face, 0.0)

    def wait(self, face: str, stop: threading.Event) -> None:
        """Block while `face` is stalled (or until the server stops)."""
        while self.stalled(face) and not stop.is_set():
            time.sleep(0.01)


class Listener:
    """Accepts connections on host:port and runs `handler(sock)` in a thread for each."""

    def __init__(
        self, host: str, port: int, handler: Callable[[socket.socket], None], name: str
    ) -> None:
        self.name = name
        self.handler = handler
        self.stop = threading.Event()
        self.sock = socket.create_server((host, port), reuse_port=False, backlog=16)
        self.sock.settimeout(POLL_S)
        self.conns: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._accept, name=f"{name}-accept", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _accept(self) -> None:
        while not self.stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn.settimeout(POLL_S)
            with self._lock:
                self.conns.add(conn)
            threading.Thread(target=self._serve, args=(conn,), name=self.name, daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        try:
            self.handler(conn)
        except OSError:
            pass
        except Exception:
            log.exception("%s connection failed", self.name)
        finally:
            with self._lock:
                self.conns.discard(conn)
            with contextlib.suppress(OSError):
                conn.close()

    def drop(self) -> int:
        """Close every open connection (the listener keeps accepting)."""
        with self._lock:
            conns = list(self.conns)
        for c in conns:
            with contextlib.suppress(OSError):
                c.shutdown(socket.SHUT_RDWR)
            with contextlib.suppress(OSError):
                c.close()
        return len(conns)

    def close(self) -> None:
        self.stop.set()
        with contextlib.suppress(OSError):
            self.sock.close()
        self.drop()
        self._thread.join(2.0)


def _recv_exact(sock: socket.socket, n: int, stop: threading.Event) -> bytes:
    """n bytes, waiting through read timeouts until the server stops; b"" on EOF."""
    buf = b""
    while len(buf) < n:
        if stop.is_set():
            return b""
        try:
            chunk = sock.recv(n - len(buf))
        except TimeoutError:
            continue
        if not chunk:
            return b""
        buf += chunk
    return buf


def serve_lines(
    sock: socket.socket,
    stop: threading.Event,
    reply: Callable[[str], str | None],
    last: str = "",
) -> None:
    """One line in, one line out until EOF or stop; `reply` returning None sends `last` and
    ends the connection."""
    buf = b""
    while not stop.is_set():
        try:
            chunk = sock.recv(4096)
        except TimeoutError:
            continue
        if not chunk:
            return
        buf += chunk
        while b"\n" in buf:
            line, buf = buf.split(b"\n", 1)
            answer = reply(line.decode(errors="replace").strip())
            sock.sendall((last if answer is None else answer).encode() + b"\n")
            if answer is None:
                return


class RTDEServer:
    """RTDE protocol 2 on port 30004: version, setup, start/pause, data packages."""

    def __init__(self, host: str, ctl: URController, faults: Faults) -> None:
        self.ctl = ctl
        self.faults = faults
        self.claims: dict[str, int] = {}
        self._claims_lock = threading.Lock()
        self.listener = Listener(host, RTDE_PORT, self._handle, "rtde")
        self.sent = 0

    def _handle(self, sock: socket.socket) -> None:
        RTDEConnection(self, sock).run()

    def claim(self, conn_id: int, names: list[str]) -> list[str]:
        """Types of an input recipe: NOT_FOUND / IN_USE where this connection may not write."""
        out = []
        with self._claims_lock:
            for name in names:
                kind = wire.INPUT_TYPES.get(name)
                owner = self.claims.get(name, conn_id)
                out.append("NOT_FOUND" if kind is None else "IN_USE" if owner != conn_id else kind)
            if all(t in wire.TYPE_FORMAT for t in out):
                for name in names:
                    self.claims[name] = conn_id
        return out

    def release(self, conn_id: int) -> None:
        with self._claims_lock:
            for name in [n for n, c in self.claims.items() if c == conn_id]:
                del self.claims[name]


class RTDEConnection:
    """One RTDE client: its output recipe, its input recipes and its sender thread."""

    _ids = iter(range(1, 1 << 30))

    def __init__(self, server: RTDEServer, sock: socket.socket) -> None:
        self.server, self.sock = server, sock
        self.id = next(self._ids)
        self.stop = server.listener.stop
        self.out_names: list[str] = []
        self.out_types: list[str] = []
        self.out_struct: struct.Struct | None = None
        self.period = 0.002
        self.inputs: dict[int, tuple[list[str], list[str], struct.Struct]] = {}
        self.started = threading.Event()
        self.closed = threading.Event()
        self.wlock = threading.Lock()

    def send(self, data: bytes) -> None:
        with self.wlock:
            self.sock.sendall(data)

    def run(self) -> None:
        sender = threading.Thread(target=self._stream, name="rtde-out", daemon=True)
        sender.start()
        try:
            while not self.stop.is_set():
                head = _recv_exact(self.sock, 3, self.stop)
                if len(head) < 3:
                    return
                size, kind = wire.HEADER.unpack(head)
                body = _recv_exact(self.sock, size - 3, self.stop) if size > 3 else b""
                if len(body) < size - 3:
                    return
                self.server.faults.wait("arm", self.stop)
                self._dispatch(kind, body)
        finally:
            self.closed.set()
            self.started.clear()
            self.server.release(self.id)

    def _dispatch(self, kind: int, body: bytes) -> None:
        ctl = self.server.ctl
        if kind == wire.REQUEST_PROTOCOL_VERSION:
            version = struct.unpack(">H", body[:2])[0] if len(body) >= 2 else 0
            self.send(wire.message(kind, bytes([1 if version in (1, 2) else 0])))
        elif kind == wire.GET_URCONTROL_VERSION:
            self.send(wire.message(kind, struct.pack(">IIII", *ctl.version)))
        elif kind == wire.SETUP_OUTPUTS:
            freq = struct.unpack(">d", body[:8])[0]
            names = [n for n in body[8:].decode(errors="replace").split(",") if n]
            types = [wire.OUTPUT_TYPES.get(n, "NOT_FOUND") for n in names]
            ok = all(t != "NOT_FOUND" for t in types) and 0 < freq <= 500
            if ok:
                self.out_names, self.out_types = names, types
                self.out_struct = wire.recipe_struct(types)
                self.period = 1.0 / freq
            self.send(wire.message(kind, bytes([1 if ok else 0]) + ",".join(types).encode()))
        elif kind == wire.SETUP_INPUTS:
            names = [n for n in body.decode(errors="replace").split(",") if n]
            types = self.server.claim(self.id, names)
            recipe = 0
            if all(t in wire.TYPE_FORMAT for t in types):
                recipe = len(self.inputs) + 1
                self.inputs[recipe] = (names, types, wire.recipe_struct(types))
            self.send(wire.message(kind, bytes([recipe]) + ",".join(types).encode()))
        elif kind == wire.START:
            ok = self.out_struct is not None or bool(self.inputs)
            if ok:
                self.started.set()
            self.send(wire.message(kind, bytes([int(ok)])))
        elif kind == wire.PAUSE:
            self.started.clear()
            self.send(wire.message(kind, b"\x01"))
        elif kind == wire.DATA_PACKAGE:
            self._input(body)
        else:
            self.send(wire.text_message(f"unknown RTDE message type {kind}", level=2))

    def _input(self, body: bytes) -> None:
        recipe = self.inputs.get(body[0]) if body else None
        if recipe is None:
            log.warning("RTDE data package for unknown input recipe %s", body[:1])
            return
        names, types, st = recipe
        if len(body) - 1 != st.size:
            log.warning(
                "RTDE data package for recipe %d has %d bytes, expected %d",
                body[0],
                len(body) - 1,
                st.size,
            )
            return
        values = wire.unflatten(types, st.unpack(body[1:]))
        self.server.ctl.write_inputs(dict(zip(names, values, strict=True)))

    def _stream(self) -> None:
        ctl, faults = self.server.ctl, self.server.faults
        next_t = time.monotonic()
        while not self.closed.is_set() and not self.stop.is_set():
            if not self.started.wait(POLL_S) or self.out_struct is None:
                next_t = time.monotonic()
                continue
            if faults.stalled("arm"):
                time.sleep(0.01)
                continue
            snap = ctl.snapshot
            values = [
                ctl.value(n, t, snap) for n, t in zip(self.out_names, self.out_types, strict=True)
            ]
            data = b"\x01" + self.out_struct.pack(*wire.flatten(self.out_types, values))
            try:
                self.send(wire.message(wire.DATA_PACKAGE, data))
            except OSError:
                return
            self.server.sent += 1
            next_t += self.period
            delay = next_t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -0.05:
                next_t = time.monotonic()


class DashboardServer:
    """UR's dashboard server on 29999: one line in, one line out."""

    def __init__(self, host: str, ctl: URController, faults: Faults) -> None:
        self.ctl = ctl
        self.faults = faults
        self.listener = Listener(host, DASHBOARD_PORT, self._handle, "dashboard")

    def _handle(self, sock: socket.socket) -> None:
        stop = self.listener.stop
        sock.sendall(b"Connected: Universal Robots Dashboard Server\n")

        def reply(line: str) -> str | None:
            self.faults.wait("dashboard", stop)
            answer = self.answer(line)
            return None if answer == "Disconnected" else answer

        serve_lines(sock, stop, reply, last="Disconnected")

    def answer(self, line: str) -> str:
        """The reply of a UR controller (PolyScope 5) to one dashboard command."""
        ctl = self.ctl
        cmd = line.lower()
        v = ".".join(str(x) for x in ctl.version)
        if cmd == "polyscopeversion":
            return f"URSoftware {v} (Oct 10 2023)"
        if cmd == "version":
            return v
        if cmd == "get serial number":
            return ctl.serial_number
        if cmd == "get robot model":
            return ctl.model.name.rstrip("e").upper()
        if cmd == "is in remote control":
            return "true"
        if cmd == "robotmode":
            return f"Robotmode: {ROBOT_MODE_NAMES.get(ctl.robot_mode, 'UNKNOWN')}"
        if cmd in ("safetymode", "safetystatus"):
            name = SAFETY_MODE_NAMES.get(ctl.safety_mode, "FAULT")
            return f"{'Safetymode' if cmd == 'safetymode' else 'Safetystatus'}: {name}"
        if cmd == "power on":
            ctl.power(True)
            return "Powering on"
        if cmd == "power off":
            ctl.power(False)
            return "Powering off"
        if cmd == "brake release":
            ctl.brake_release()
            return "Brake releasing"
        if cmd == "unlock protective stop":
            return ctl.unlock_protective_stop()
        if cmd == "close safety popup":
            return "closing safety popup"
        if cmd == "close popup":
            return "closing popup"
        if cmd == "restart safety":
            ctl.release_emergency_stop()
            return "Restarting safety"
        if cmd == "stop":  # idempotent: ur-rtde's reconnect sends it after stopping its script
            ctl.stop_program("dashboard stop")
            return "Stopped"
        if cmd == "pause":
            return "Failed to execute: pause"
        if cmd == "play":
            return "Failed to execute: play"
        if cmd == "running":
            return f"Program running: {str(ctl.runtime_state == 2).lower()}"
        if cmd == "programstate":
            state = "PLAYING" if ctl.runtime_state == 2 else "STOPPED"
            return f"{state} {ctl.loaded_program or '<unnamed>'}"
        if cmd == "get loaded program":
            return (
                f"Loaded program: {ctl.loaded_program}"
                if ctl.loaded_program
                else ("No program loaded")
            )
        if cmd == "isprogramsaved":
            return "true"
        if cmd.startswith("addtolog"):
            return "Added log message"
        if cmd.startswith("popup"):
            return "showing popup"
        if cmd == "quit":
            return "Disconnected"
        if cmd.startswith("load"):
            return f"File not found: {line[5:].strip()}"
        return f"could not understand: '{line}'"


_PROGRAM_END = re.compile(rb"^end[ \t\r]*$", re.MULTILINE)


class ScriptServer:
    """The script port (30003): complete programs are handed to the controller."""

    def __init__(self, host: str, ctl: URController, faults: Faults) -> None:
        self.ctl = ctl
        self.faults = faults
        self.listener = Listener(host, SCRIPT_PORT, self._handle, "script")
        self.programs = 0

    def _handle(self, sock: socket.socket) -> None:
        stop = self.listener.stop
        buf = b""
        while not stop.is_set():
            try:
                chunk = sock.recv(65536)
            except TimeoutError:
                continue
            if not chunk:
                return
            buf += chunk
            buf = self._consume(buf)

    def _consume(self, buf: bytes) -> bytes:
        while True:
            start = buf.find(b"def ")
            if start < 0:
                start = buf.find(b"sec ")
            if start < 0:
                if buf.endswith(b"\n") and buf.strip():
                    log.warning("script port: %r is not interpreted", buf[:80])
                    return b""
                return buf
            end = _PROGRAM_END.search(buf, start)
            if end is None:
                return buf
            program = buf[start : end.end()].decode(errors="replace")
            buf = buf[end.end() :].lstrip(b"\r\n")
            self.programs += 1
            self.ctl.run_script(program)


def all_status(ctl: URController) -> dict[str, Any]:
    """Controller state for the control channel."""
    import numpy as np

    with ctl.lock:
        return {
            "robot_mode": ROBOT_MODE_NAMES.get(ctl.robot_mode, str(ctl.robot_mode)),
            "safety_mode": SAFETY_MODE_NAMES.get(ctl.safety_mode, str(ctl.safety_mode)),
            "program_running": ctl.runtime_state == 2,
            "moving": ctl.moving,
            "q_deg": np.rad2deg(ctl.q).tolist(),
            "tcp_pose": ctl.tcp_pose(),
            "digital_output_bits": ctl.outputs.bits,
            "commands": list(ctl.events.commands),
            "motions": ctl.events.motions,
            "last_motion_s": ctl.events.last_motion_s,
            "scripts": ctl.events.scripts,
            "refused_scripts": ctl.events.refused_scripts,
        }
