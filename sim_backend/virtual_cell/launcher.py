"""Start a virtual cell as a subprocess and talk to its control channel (tests, demo, bench).

    with VirtualCellProcess("sorting", width=320) as vc:    # picks a free 127.a.b.c
        vc.host                                             # where the drivers connect
        vc.control("protective_stop"); vc.truth()

The process is ready when it prints `ready HOST` (every port accepts); `stop()` sends SIGTERM
and waits, then kills. Every wait has a timeout.
"""

from __future__ import annotations

import contextlib
import os
import queue
import random
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from omnisort_hw.sim_link import SimControlError, SimLink
from sim_backend.virtual_cell.camera_stream import CAMERA_PORT
from sim_backend.virtual_cell.cell import CONTROL_PORT
from sim_backend.virtual_cell.laser_modbus import MODBUS_PORT
from sim_backend.virtual_cell.servers import DASHBOARD_PORT, RTDE_PORT, SCRIPT_PORT

PORTS = (RTDE_PORT, DASHBOARD_PORT, SCRIPT_PORT, MODBUS_PORT, CAMERA_PORT, CONTROL_PORT)


def free_loopback_host(rng: random.Random | None = None, tries: int = 50) -> str:
    """A random 127.a.b.c (never 127.0.0.1) whose cell ports are all free right now."""
    rng = rng or random.Random()
    for _ in range(tries):
        host = f"127.{rng.randint(1, 254)}.{rng.randint(0, 255)}.{rng.randint(2, 254)}"
        try:
            socks = []
            for port in PORTS:
                s = socket.socket()
                socks.append(s)
                s.bind((host, port))
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
        return host
    raise RuntimeError("no free loopback address for a virtual cell")


class VirtualCellError(RuntimeError):
    """The virtual cell did not start, or its control channel failed."""


class VirtualCellProcess:
    """One `omnisort sim virtual-cell` subprocess on its own loopback address."""

    def __init__(
        self,
        scene: str = "sorting",
        host: str | None = None,
        *,
        width: int | None = None,
        unlock_delay_s: float = 0.2,
        extra: list[str] | None = None,
        start_timeout_s: float = 120.0,
    ) -> None:
        self.scene = scene
        self.host = host or free_loopback_host()
        self.args = [
            sys.executable,
            "-m",
            "omnisort_hw.cli",
            "sim",
            "virtual-cell",
            "--scene",
            scene,
            "--host",
            self.host,
            "--unlock-delay",
            str(unlock_delay_s),
        ]
        if width:
            self.args += ["--width", str(width)]
        self.args += extra or []
        self.start_timeout_s = start_timeout_s
        self.proc: subprocess.Popen[str] | None = None
        self.log_path = Path(tempfile.mkstemp(prefix="virtual-cell-", suffix=".log")[1])
        self._lines: queue.Queue[str] = queue.Queue()
        self.link = SimLink(self.host, CONTROL_PORT)

    def start(self) -> VirtualCellProcess:
        root = Path(__file__).resolve().parents[2]
        env = dict(os.environ, PYTHONPATH=f"{root}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
        log = self.log_path.open("w")
        self.proc = subprocess.Popen(
            self.args, stdout=subprocess.PIPE, stderr=log, text=True, env=env, cwd=root
        )
        log.close()
        threading.Thread(target=self._read_stdout, daemon=True).start()
        deadline = time.monotonic() + self.start_timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                self.stop()
                raise VirtualCellError(f"virtual cell on {self.host} not ready: {self.log_tail()}")
            try:
                line = self._lines.get(timeout=min(remaining, 0.5))
            except queue.Empty:
                if self.proc.poll() is not None:
                    raise VirtualCellError(
                        f"virtual cell exited with {self.proc.returncode}: {self.log_tail()}"
                    ) from None
                continue
            if line.strip() == f"ready {self.host}":
                return self

    def _read_stdout(self) -> None:
        assert self.proc is not None and self.proc.stdout is not None
        for line in self.proc.stdout:
            self._lines.put(line)

    def log_tail(self, n: int = 3000) -> str:
        with contextlib.suppress(OSError):
            return self.log_path.read_text()[-n:]
        return ""

    def control(self, cmd: str, timeout_s: float = 10.0, **args: Any) -> dict[str, Any]:
        """One control-channel request; its result (VirtualCellError on failure)."""
        try:
            return self.link.control(cmd, timeout_s, **args)
        except SimControlError as exc:
            raise VirtualCellError(exc.message) from exc

    def truth(self) -> dict[str, Any]:
        return self.control("truth")

    def dashboard(self, *lines: str, timeout_s: float = 5.0) -> list[str]:
        """Send dashboard commands (as a technician or ur-rtde would); their replies."""
        with socket.create_connection((self.host, DASHBOARD_PORT), timeout=timeout_s) as s:
            f = s.makefile("rwb")
            f.readline()
            replies = []
            for line in lines:
                f.write(line.encode() + b"\n")
                f.flush()
                replies.append(f.readline().decode().strip())
            return replies

    def kill(self) -> None:
        """Pull the plug: SIGKILL, no clean shutdown."""
        self.link.close()
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10.0)

    def stop(self, timeout_s: float = 15.0) -> int | None:
        """SIGTERM, wait up to timeout_s, then SIGKILL; the exit code."""
        self.link.close()
        if self.proc is None:
            return None
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10.0)
        return self.proc.returncode

    def __enter__(self) -> VirtualCellProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
