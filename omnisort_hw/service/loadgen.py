"""Hostile and ordinary client loads for checking a service under faults, from outside.

Used by the fault tests, `benchmarks/bench_faults.py` and the soak, and usable against a
commissioned cell: idle connections held, a client that sends without ever reading, `status`
polled at a fixed rate, one-shot round trips, and the process's RSS and open descriptors read
from /proc (Linux).
"""

from __future__ import annotations

import json
import os
import socket
import statistics
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


def rss_bytes(pid: int) -> int:
    """Resident set size of process `pid` (VmRSS), bytes."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise RuntimeError(f"/proc/{pid}/status has no VmRSS")


def open_fds(pid: int) -> int:
    """How many file descriptors process `pid` has open."""
    return len(os.listdir(f"/proc/{pid}/fd"))


def round_trip(
    host: str, port: int, cmd: str, source: str = "127.0.0.1", timeout_s: float = 10.0
) -> tuple[dict[str, Any], float]:
    """Connect (from `source`), send one request, read its reply: (reply, seconds)."""
    t0 = time.perf_counter()
    with socket.create_connection((host, port), timeout_s, source_address=(source, 0)) as s:
        s.sendall(json.dumps({"id": 1, "cmd": cmd}).encode() + b"\n")
        buf = b""
        while b"\n" not in buf:
            chunk = s.recv(65536)
            if not chunk:
                raise ConnectionError(f"{cmd}: connection closed without a reply")
            buf += chunk
    return json.loads(buf.split(b"\n", 1)[0]), time.perf_counter() - t0


@contextmanager
def idle_connections(
    host: str, port: int, n: int, sources: list[str] | None = None
) -> Iterator[list[socket.socket]]:
    """`n` connections that send nothing, spread over the loopback `sources` addresses."""
    srcs = sources or ["127.0.0.1"]
    socks: list[socket.socket] = []
    try:
        for i in range(n):
            src = (srcs[i % len(srcs)], 0)
            socks.append(socket.create_connection((host, port), 10.0, source_address=src))
        yield socks
    finally:
        for s in socks:
            s.close()


@dataclass
class FloodResult:
    """What a never-reading client managed to send."""

    sent: int = 0
    connections: int = 0
    dropped_by_server: int = 0
    seconds: float = 0.0


def never_reading_flood(
    host: str,
    port: int,
    requests: int,
    stop: threading.Event | None = None,
    batch: int = 500,
    stall_s: float = 60.0,
    hold_s: float = 0.0,
) -> FloodResult:
    """Send `requests` pipelined `status` lines and never read a reply; reconnect whenever the
    service drops the connection. Requests count as sent once the kernel took them. Then keep
    the last connection open, still not reading, for up to `hold_s` or until it is dropped."""
    stop = stop or threading.Event()
    out = FloodResult()
    t0 = time.monotonic()
    line = b'{"id": 1, "cmd": "status"}\n'
    sock: socket.socket | None = None
    pending = b""
    try:
        while out.sent < requests and not stop.is_set():
            if sock is None:
                sock = socket.create_connection((host, port), 10.0)
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
                sock.settimeout(stall_s)
                out.connections += 1
                pending = b""
            if not pending:
                pending = line * min(batch, requests - out.sent)
            try:
                n = sock.send(pending)
            except (ConnectionError, TimeoutError, OSError):
                out.dropped_by_server += 1
                sock.close()
                sock = None
                continue
            out.sent += pending[:n].count(b"\n")
            pending = pending[n:]
        if sock is not None and _dropped_within(sock, hold_s, stop):
            out.dropped_by_server += 1
    finally:
        if sock is not None:
            sock.close()
    out.seconds = time.monotonic() - t0
    return out


def _dropped_within(sock: socket.socket, hold_s: float, stop: threading.Event) -> bool:
    """True when the peer drops `sock` within `hold_s` (probed by non-blocking sends; a full
    buffer means still connected). Nothing is read."""
    sock.setblocking(False)
    deadline = time.monotonic() + hold_s
    while time.monotonic() < deadline and not stop.is_set():
        try:
            sock.send(b"\n")
        except BlockingIOError:
            pass
        except OSError:
            return True
        time.sleep(0.05)
    return False


@dataclass
class StatusPoller:
    """Polls `status` every `period_s` on one connection in a thread; latencies and errors."""

    host: str
    port: int
    period_s: float = 0.05
    timeout_s: float = 5.0
    latencies: list[float] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="status-poller", daemon=True)

    def _run(self) -> None:
        from omnisort_hw.service.client import Client

        try:
            client = Client(self.host, self.port, timeout_s=self.timeout_s)
        except Exception as exc:
            self.errors.append(f"connect: {exc}")
            return
        with client:
            next_t = time.monotonic()
            while not self._stop.is_set():
                t0 = time.perf_counter()
                try:
                    reply = client.call("status")
                except Exception as exc:
                    self.errors.append(repr(exc))
                    return
                self.latencies.append(time.perf_counter() - t0)
                if not reply.get("ok"):
                    self.errors.append(json.dumps(reply)[:200])
                next_t += self.period_s
                time.sleep(max(0.0, next_t - time.monotonic()))

    def __enter__(self) -> StatusPoller:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(self.timeout_s + 1.0)

    def summary(self) -> dict[str, Any]:
        lat = sorted(self.latencies)
        if not lat:
            return {"requests": 0, "errors": len(self.errors)}
        return {
            "requests": len(lat),
            "errors": len(self.errors),
            "median_ms": round(statistics.median(lat) * 1e3, 3),
            "p99_ms": round(lat[int(0.99 * (len(lat) - 1))] * 1e3, 3),
            "max_ms": round(lat[-1] * 1e3, 3),
        }
