"""Start `omnisort serve` as a child process the way systemd does, and learn its port.

The child gets a NOTIFY_SOCKET owned by the caller; its READY=1 notification carries
`STATUS=idle; listening on HOST:PORT`, so `--port 0` (any free port) works without races. Used
by the service demo, the end-to-end tests and the benchmark.
"""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

READY_RE = re.compile(r"READY=1[\s\S]*listening on ([\d.:a-fA-F]+):(\d+)")


@dataclass
class ServiceProcess:
    """A running `omnisort serve` child: its process, port, notify socket and log file."""

    proc: subprocess.Popen[bytes]
    host: str
    port: int
    notify: socket.socket
    log_path: Path
    notifications: list[str] = field(default_factory=list)

    def stop(self, timeout_s: float = 60.0) -> int | None:
        """SIGTERM, wait for the clean exit; SIGKILL if it does not come. Returns the code."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)
        self.notify.close()
        return self.proc.returncode

    def __enter__(self) -> ServiceProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _drain(rx: socket.socket, sink: list[str]) -> None:
    """Keep reading the notify socket (STATUS= on every state change) until it is closed."""
    rx.settimeout(1.0)
    while True:
        try:
            sink.append(rx.recv(4096).decode("utf-8", "replace"))
        except TimeoutError:
            continue
        except OSError:
            return


def start_service(
    config: Path,
    workdir: Path,
    timeout_s: float = 120.0,
    extra_env: dict[str, str] | None = None,
    port: int = 0,
) -> ServiceProcess:
    """Run `python -m omnisort_hw.cli serve --config CONFIG --port PORT` (0: any free port);
    return once READY.

    The child's stdout and stderr go to WORKDIR/serve.log; the notify socket is
    WORKDIR/notify.sock. Raises RuntimeError with the log's tail if it does not get ready.
    """
    # NOTIFY_SOCKET must be absolute (or abstract): systemd's protocol ignores relative paths.
    workdir = workdir.resolve()
    workdir.mkdir(parents=True, exist_ok=True)
    sock_path = workdir / "notify.sock"
    sock_path.unlink(missing_ok=True)
    rx = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    rx.bind(str(sock_path))
    rx.settimeout(timeout_s)
    env = {k: v for k, v in os.environ.items() if k not in {"WATCHDOG_USEC", "WATCHDOG_PID"}}
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    env["NOTIFY_SOCKET"] = str(sock_path)
    env.update(extra_env or {})
    log_path = workdir / "serve.log"
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "omnisort_hw.cli",
                "serve",
                "--config",
                str(config),
                "--port",
                str(port),
            ],
            stdout=log,
            stderr=subprocess.STDOUT,
            env=env,
        )
    seen: list[str] = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            msg = rx.recv(4096).decode("utf-8", "replace")
        except TimeoutError:
            break
        seen.append(msg)
        m = READY_RE.search(msg)
        if m:
            threading.Thread(target=_drain, args=(rx, seen), daemon=True).start()
            return ServiceProcess(proc, m.group(1), int(m.group(2)), rx, log_path, seen)
    if proc.poll() is None:
        proc.kill()
        proc.wait(10)
    rx.close()
    tail = log_path.read_text(errors="replace")[-3000:]
    raise RuntimeError(f"the service did not become ready (exit {proc.returncode}):\n{tail}")
