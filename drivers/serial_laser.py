"""Laser switch on a serial line (pyserial) with a configurable line protocol.

The protocol is one command line per request and one reply line per command, for example
`LASER ON` -> `OK`, `LASER?` -> `ON`. Every switch is followed by a query, and the call returns
only when the device reports the requested state. Each exchange has a timeout; timeouts and
garbage replies are retried a bounded number of times, then raised as `DeviceTimeoutError` or
`BadReplyError`. Stale input is flushed before every request so a late answer to an earlier
request is not taken for the answer to the current one.
"""

from __future__ import annotations

import select
import termios
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar, Literal, TypeVar

import serial

from drivers._common import classify_open_error, log, require
from drivers.base import LaserSwitch
from drivers.errors import (
    BadReplyError,
    DeviceDisconnectedError,
    DeviceError,
    DeviceTimeoutError,
)

T = TypeVar("T")


@dataclass(frozen=True)
class SerialLaserConfig:
    """Settings of `[laser]` with `backend = "serial"`.

    `ack_reply = ""` means the device sends no acknowledgement after on/off commands (the
    read-back query is then the only confirmation). Replies are compared after stripping
    whitespace; a reply may end with CR, LF or CRLF whatever `line_ending` the commands use.
    """

    SECTION: ClassVar[str] = "laser"

    port: str
    baudrate: int = 9600
    bytesize: int = 8
    parity: Literal["N", "E", "O"] = "N"
    stopbits: int = 1
    on_command: str = "LASER ON"
    off_command: str = "LASER OFF"
    query_command: str = "LASER?"
    ack_reply: str = "OK"
    on_reply: str = "ON"
    off_reply: str = "OFF"
    line_ending: str = "\r\n"
    timeout_s: float = 0.5
    retries: int = 2
    exclusive: bool = True

    def __post_init__(self) -> None:
        s = self.SECTION
        require(bool(self.port), s, "port", "give the serial device, e.g. /dev/ttyUSB0")
        require(self.baudrate > 0, s, "baudrate", f"must be positive, got {self.baudrate}")
        require(self.bytesize in (5, 6, 7, 8), s, "bytesize", "must be 5, 6, 7 or 8")
        require(self.parity in ("N", "E", "O"), s, "parity", "must be 'N', 'E' or 'O'")
        require(self.stopbits in (1, 2), s, "stopbits", "must be 1 or 2")
        require(self.timeout_s > 0, s, "timeout_s", f"must be > 0, got {self.timeout_s}")
        require(0 <= self.retries <= 10, s, "retries", f"must be 0..10, got {self.retries}")
        require(bool(self.line_ending), s, "line_ending", "must not be empty")
        for key in ("on_command", "off_command", "query_command", "on_reply", "off_reply"):
            require(bool(getattr(self, key).strip()), s, key, "must not be empty")
        require(self.on_reply != self.off_reply, s, "on_reply", "must differ from off_reply")


class SerialLaser(LaserSwitch):
    """A laser switch behind a serial line protocol. Thread-safe: one exchange at a time."""

    def __init__(self, config: SerialLaserConfig) -> None:
        self.config = config
        self._ser: serial.Serial | None = None
        self._lock = threading.RLock()
        self._lost = False

    @property
    def name(self) -> str:
        return f"serial laser switch on {self.config.port}"

    @property
    def is_connected(self) -> bool:
        return self._ser is not None and self._ser.is_open

    def connect(self) -> None:
        """Open the port (exclusively unless configured otherwise) and query the state once."""
        with self._lock:
            if self.is_connected:
                return
            self._open()
            try:
                self.state()
            except DeviceError:
                self.close()
                raise

    def close(self) -> None:
        with self._lock:
            ser, self._ser = self._ser, None
            self._lost = False
            if ser is not None:
                try:
                    ser.close()
                except (OSError, termios.error, serial.SerialException):
                    log.debug("closing %s failed", self.config.port, exc_info=True)

    def _open(self) -> None:
        cfg = self.config
        ser = serial.Serial()
        ser.port = cfg.port
        ser.baudrate = cfg.baudrate
        ser.bytesize = cfg.bytesize
        ser.parity = cfg.parity
        ser.stopbits = cfg.stopbits
        ser.timeout = 0  # reads are non-blocking; _exchange waits with select() to its deadline
        ser.write_timeout = cfg.timeout_s
        ser.exclusive = cfg.exclusive
        try:
            ser.open()
        except (OSError, termios.error, serial.SerialException) as exc:
            raise classify_open_error(exc, cfg.port, "serial port") from exc
        ser.reset_input_buffer()
        self._ser = ser
        self._lost = False

    def _port(self) -> serial.Serial:
        """The open port; reopens once (logged) after a lost connection, never after close()."""
        if self._ser is not None and self._ser.is_open:
            return self._ser
        if not self._lost:
            raise DeviceDisconnectedError(
                f"{self.name} is not connected: call connect() first", device=self.config.port
            )
        log.warning("%s: connection was lost, reopening the port", self.name)
        self._open()
        log.info("%s: port reopened", self.name)
        return self._ser

    def _lose(self, exc: BaseException, doing: str) -> DeviceDisconnectedError:
        ser, self._ser = self._ser, None
        self._lost = True
        if ser is not None:
            try:
                ser.close()
            except (OSError, termios.error, serial.SerialException):
                log.debug("closing %s after a failure failed", self.config.port, exc_info=True)
        log.warning("%s: lost while %s: %s", self.name, doing, exc)
        return DeviceDisconnectedError(
            f"{self.name} went away while {doing} ({exc}): check the cable and the adapter",
            device=self.config.port,
        )

    def _exchange(self, command: str, deadline: float) -> str:
        """Send one command line and return the first non-empty reply line (stripped)."""
        cfg = self.config
        ser = self._port()
        timeout = min(cfg.timeout_s, deadline - time.monotonic())
        if timeout <= 0:
            raise DeviceTimeoutError(f"{self.name}: no time left for {command!r}", device=cfg.port)
        end = time.monotonic() + timeout
        try:
            ser.reset_input_buffer()
            ser.write((command + cfg.line_ending).encode("ascii"))
            ser.flush()
            buf = bytearray()
            while True:
                del buf[: len(buf) - len(buf.lstrip(b"\r\n"))]
                ends = [i for i in (buf.find(b"\n"), buf.find(b"\r")) if i >= 0]
                if ends:
                    return self._decode(bytes(buf[: min(ends)]), command)
                remaining = end - time.monotonic()
                if remaining <= 0:
                    raise DeviceTimeoutError(
                        f"{self.name} did not answer {command!r} within {timeout:.2f} s"
                        + (f" (partial reply {bytes(buf)!r})" if buf else "")
                        + ": is it powered, on this port, at [laser].baudrate "
                        f"{cfg.baudrate}?",
                        device=cfg.port,
                    )
                readable, _, _ = select.select([ser.fileno()], [], [], remaining)
                if readable:
                    buf.extend(ser.read(max(1, ser.in_waiting)))
                if len(buf) > 1024:
                    raise BadReplyError(
                        f"{self.name} sent {len(buf)} bytes without a line ending "
                        f"({bytes(buf[:40])!r}...): check [laser].line_ending and baudrate",
                        device=cfg.port,
                    )
        except serial.SerialTimeoutException as exc:
            raise DeviceTimeoutError(
                f"{self.name}: could not send {command!r} within {timeout:.2f} s (output "
                "blocked: flow control or a hung adapter)",
                device=cfg.port,
            ) from exc
        except (OSError, termios.error, serial.SerialException) as exc:
            raise self._lose(exc, f"sending {command!r}") from exc

    def _decode(self, line: bytes, command: str) -> str:
        try:
            return line.decode("ascii").strip()
        except UnicodeDecodeError:
            raise BadReplyError(
                f"{self.name} answered {command!r} with non-text bytes {line!r}: check "
                "[laser].baudrate and the wiring",
                device=self.config.port,
            ) from None

    def _parse_state(self, reply: str) -> bool:
        cfg = self.config
        if reply == cfg.on_reply:
            return True
        if reply == cfg.off_reply:
            return False
        raise BadReplyError(
            f"{self.name} answered {cfg.query_command!r} with {reply!r}, expected "
            f"{cfg.on_reply!r} or {cfg.off_reply!r}: check the [laser] protocol settings",
            device=cfg.port,
        )

    def _budget(self, timeout_s: float | None, exchanges: int) -> float:
        if timeout_s is not None:
            return time.monotonic() + timeout_s
        return time.monotonic() + (self.config.retries + 1) * exchanges * self.config.timeout_s

    def _retrying(self, what: str, deadline: float, attempt_fn: Callable[[], T]) -> T:
        """Run `attempt_fn()` up to 1 + retries times while time remains; re-raise the last."""
        last: DeviceTimeoutError | BadReplyError | None = None
        tries = 0
        while tries <= self.config.retries and time.monotonic() < deadline:
            tries += 1
            try:
                return attempt_fn()
            except (DeviceTimeoutError, BadReplyError) as exc:
                last = exc
                log.warning("%s: %s attempt %d failed: %s", self.name, what, tries, exc)
        if last is None:
            raise DeviceTimeoutError(
                f"{self.name}: timeout before {what} could start", device=self.config.port
            )
        raise type(last)(f"{last} [{what}: {tries} attempt(s)]", device=self.config.port) from last

    def state(self, timeout_s: float | None = None) -> bool:
        """Query the device (`query_command`) and return True when it reports `on_reply`."""
        with self._lock:
            deadline = self._budget(timeout_s, 1)
            return self._retrying(
                "query",
                deadline,
                lambda: self._parse_state(self._exchange(self.config.query_command, deadline)),
            )

    def set(self, on: bool, timeout_s: float | None = None) -> None:
        """Send the on/off command, check the acknowledgement, then read the state back."""
        cfg = self.config
        command = cfg.on_command if on else cfg.off_command

        def attempt() -> None:
            reply = self._exchange(command, deadline)
            if cfg.ack_reply and reply != cfg.ack_reply:
                raise BadReplyError(
                    f"{self.name} answered {command!r} with {reply!r}, expected "
                    f"{cfg.ack_reply!r}: check [laser].ack_reply",
                    device=cfg.port,
                )
            actual = self._parse_state(self._exchange(cfg.query_command, deadline))
            if actual != on:
                raise BadReplyError(
                    f"{self.name} acknowledged {command!r} but reads back "
                    f"{'ON' if actual else 'OFF'}: the laser did not switch (interlock? driver "
                    "fault?)",
                    device=cfg.port,
                )

        with self._lock:
            deadline = self._budget(timeout_s, 2)
            self._retrying(f"switch {'on' if on else 'off'}", deadline, attempt)
