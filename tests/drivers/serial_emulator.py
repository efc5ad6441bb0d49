"""A laser switch emulated on the master side of a pseudo-terminal (`os.openpty`).

The driver under test opens `emulator.path` (the pty's slave) with pyserial exactly as it would
open `/dev/ttyUSB0`, so every byte goes through the kernel's tty layer. The emulator speaks the
default `SerialLaserConfig` protocol and can misbehave on purpose (`mode`):

* "normal"  answers at once; "late" answers after `delay_s`;
* "silent"  reads commands and never answers;
* "garbage" answers random non-protocol bytes; "stuck" acknowledges but never switches.
"""

from __future__ import annotations

import os
import select
import threading
import time
import tty
from typing import Literal

Mode = Literal["normal", "late", "silent", "garbage", "stuck"]


class SerialDeviceEmulator:
    """Runs in a daemon thread; `close()` (or `unplug()`) stops it and closes the master."""

    def __init__(self, mode: Mode = "normal", delay_s: float = 0.0, eol: bytes = b"\r\n") -> None:
        self.mode: Mode = mode
        self.delay_s = delay_s
        self.eol = eol
        self.laser_on = False
        self.received: list[str] = []
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.path = os.ttyname(self._slave)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="serial-emulator", daemon=True)
        self._thread.start()

    def _reply(self, command: str) -> bytes | None:
        if self.mode == "silent":
            return None
        if self.mode == "garbage":
            return b"\x15?#\xfe!" + self.eol
        if self.mode == "late":
            time.sleep(self.delay_s)
        if command == "LASER ON":
            if self.mode != "stuck":
                self.laser_on = True
            return b"OK" + self.eol
        if command == "LASER OFF":
            self.laser_on = False
            return b"OK" + self.eol
        if command == "LASER?":
            return (b"ON" if self.laser_on else b"OFF") + self.eol
        return b"ERR" + self.eol

    def _run(self) -> None:
        buf = b""
        try:
            while not self._stop.is_set():
                readable, _, _ = select.select([self.master], [], [], 0.02)
                if not readable:
                    continue
                try:
                    data = os.read(self.master, 1024)
                except OSError:
                    time.sleep(0.01)
                    continue
                buf += data
                while True:
                    cut = [i for i in (buf.find(b"\r"), buf.find(b"\n")) if i >= 0]
                    if not cut:
                        break
                    line, buf = buf[: min(cut)], buf[min(cut) + 1 :]
                    text = line.decode("ascii", "replace").strip()
                    if not text:
                        continue
                    self.received.append(text)
                    reply = self._reply(text)
                    if reply is not None and not self._stop.is_set():
                        os.write(self.master, reply)
        finally:
            os.close(self.master)
            os.close(self._slave)

    def unplug(self) -> None:
        """The device goes away: the pty is closed, the driver's next read/write fails."""
        self._stop.set()
        self._thread.join(timeout=2.0)

    close = unplug

    def __enter__(self) -> SerialDeviceEmulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
