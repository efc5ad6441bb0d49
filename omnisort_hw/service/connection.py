"""Reading request lines with time bounds, and admitting connections per client and per peer.

`LineReader` yields one request line at a time from a stream and enforces two clocks: a line
that has started must end (newline) within `line_timeout_s`, and a connection with nothing in
flight that sends nothing for `idle_timeout_s` is closed. It never buffers more than
`max_line_bytes` of one line, so a hostile line costs a bounded amount of memory.

`Admission` counts connections overall and per peer address. A connection over either limit
is not dropped at once: it may still send one `stop` or `estop` (the reserved path), and is
closed after that line or after a short grace period. The number of such connections is
bounded as well.
"""

from __future__ import annotations

import asyncio
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass

READ_CHUNK = 65536
TOO_LONG = object()


class LineTimeoutError(Exception):
    """A line was started but its newline did not arrive in time."""


class IdleTimeoutError(Exception):
    """Nothing arrived for the idle timeout while the connection had nothing in flight."""


class LineReader:
    """Request lines from `reader`; TOO_LONG once for each over-long line (then skipped)."""

    def __init__(
        self,
        reader: asyncio.StreamReader,
        max_line_bytes: int,
        line_timeout_s: float,
        idle_timeout_s: float | None,
        busy: Callable[[], bool] = lambda: False,
    ) -> None:
        self._reader = reader
        self._limit = max_line_bytes
        self._line_timeout_s = line_timeout_s
        self._idle_timeout_s = idle_timeout_s
        self._busy = busy
        self._buf = bytearray()
        self._skipping = False
        self._ready: deque[bytes | object] = deque()
        self._line_started: float | None = None
        self._last_activity = time.monotonic()
        self._eof = False

    def _deadline(self) -> tuple[float | None, str]:
        if self._line_started is not None:
            return self._line_started + self._line_timeout_s, "line"
        if self._idle_timeout_s is None:
            return None, "idle"
        return self._last_activity + self._idle_timeout_s, "idle"

    async def next(self) -> bytes | object | None:
        """The next line (without its newline), TOO_LONG, or None at the end of the stream."""
        while not self._ready:
            if self._eof:
                return None
            deadline, what = self._deadline()
            timeout = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                chunk = await asyncio.wait_for(self._reader.read(READ_CHUNK), timeout)
            except TimeoutError:
                if what == "line":
                    raise LineTimeoutError(
                        f"no end of line within {self._line_timeout_s:g} s"
                    ) from None
                if self._busy():
                    self._last_activity = time.monotonic()
                    continue
                raise IdleTimeoutError(f"idle for {self._idle_timeout_s:g} s") from None
            self._last_activity = time.monotonic()
            if not chunk:
                self._eof = True
                if self._buf and not self._skipping:
                    self._ready.append(bytes(self._buf))
                self._buf.clear()
                continue
            self._split(chunk)
        return self._ready.popleft()

    def _split(self, chunk: bytes) -> None:
        start = 0
        while True:
            nl = chunk.find(b"\n", start)
            if nl < 0:
                rest = chunk[start:]
                if rest and self._line_started is None:
                    self._line_started = time.monotonic()
                if not self._skipping:
                    self._buf += rest
                    if len(self._buf) > self._limit:
                        self._buf.clear()
                        self._skipping = True
                        self._ready.append(TOO_LONG)
                return
            self._line_started = None
            if self._skipping:
                self._skipping = False
            else:
                self._buf += chunk[start:nl]
                if len(self._buf) > self._limit:
                    self._ready.append(TOO_LONG)
                else:
                    buf = self._buf
                    self._ready.append(bytes(buf[:-1] if buf.endswith(b"\r") else buf))
                self._buf.clear()
            start = nl + 1


@dataclass
class Admission:
    """Connection counts overall and per peer; `admit` says why a new one is over a limit."""

    max_clients: int
    max_per_peer: int
    max_overflow: int

    def __post_init__(self) -> None:
        self.clients = 0
        self.overflow = 0
        self.per_peer: Counter[str] = Counter()

    def admit(self, peer: str) -> str | None:
        """Count a new connection from `peer`; None when admitted, else the refusal."""
        if self.clients >= self.max_clients:
            return f"too many clients ({self.max_clients})"
        if self.per_peer[peer] >= self.max_per_peer:
            return f"too many connections from {peer} ({self.max_per_peer})"
        self.clients += 1
        self.per_peer[peer] += 1
        return None

    def release(self, peer: str) -> None:
        self.clients -= 1
        self.per_peer[peer] -= 1
        if self.per_peer[peer] <= 0:
            del self.per_peer[peer]

    def enter_overflow(self) -> bool:
        """Count a connection kept only for one stop/estop; False when too many are held."""
        if self.overflow >= self.max_overflow:
            return False
        self.overflow += 1
        return True

    def leave_overflow(self) -> None:
        self.overflow -= 1


def peer_host(peername: object) -> str:
    """The address part of a socket's peer name ('?' when unknown)."""
    if isinstance(peername, tuple) and peername:
        return str(peername[0])
    return "?"
