"""Start the fake-device service (`fake_service.py`) as a subprocess for end-to-end tests."""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parents[2]


def start_service(
    tmp: Path, *extra: str, env: dict[str, str] | None = None
) -> tuple[subprocess.Popen[bytes], str, int]:
    """Run the service in a subprocess; returns (process, host, port) once it listens.

    The systemd variables are removed from the inherited environment unless given in `env`.
    """
    full = {
        k: v
        for k, v in os.environ.items()
        if k not in {"NOTIFY_SOCKET", "WATCHDOG_USEC", "WATCHDOG_PID"}
    }
    full["PYTHONPATH"] = str(PROJECT_ROOT)
    full.update(env or {})
    (tmp / "state").mkdir(parents=True, exist_ok=True)
    with open(tmp / "stderr.txt", "wb") as err:
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "tests.service.fake_service",
                str(tmp / "state"),
                str(tmp / "logs"),
                *extra,
            ],
            stdout=subprocess.PIPE,
            stderr=err,
            env=full,
            cwd=PROJECT_ROOT,
        )
    assert proc.stdout is not None
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if line.startswith(b"LISTENING"):
            _, host, port = line.split()
            return proc, host.decode(), int(port)
        if not line and proc.poll() is not None:
            break
    proc.kill()
    proc.wait(10)
    raise AssertionError(f"service did not start: {(tmp / 'stderr.txt').read_text()[-2000:]}")


def _drain(rx: socket.socket) -> None:
    """Keep reading the notify socket (STATUS= on every state change) until it is closed."""
    rx.settimeout(1.0)
    while True:
        try:
            rx.recv(4096)
        except TimeoutError:
            continue
        except OSError:
            return


def start_serve(
    cfg: Path, tmp: Path, timeout_s: float = 120.0
) -> tuple[subprocess.Popen[bytes], int, socket.socket]:
    """`omnisort serve --config CFG --port 0` as under systemd: READY and the bound port come
    over a real NOTIFY_SOCKET. Returns (process, port, notify socket); the service's output goes
    to TMP/serve.log. Close the socket after the process has ended."""
    sock_path = str(tmp / "notify.sock")
    rx = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    rx.bind(sock_path)
    rx.settimeout(timeout_s)
    env = {k: v for k, v in os.environ.items() if k not in {"WATCHDOG_USEC", "WATCHDOG_PID"}}
    env.update(NOTIFY_SOCKET=sock_path, PYTHONPATH=str(PROJECT_ROOT))
    with open(tmp / "serve.log", "wb") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "omnisort_hw.cli", "serve", "--config", str(cfg), "--port", "0"],
            stdout=log,
            stderr=subprocess.STDOUT,
            env=env,
            cwd=PROJECT_ROOT,
        )
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            msg = rx.recv(4096).decode()
        except TimeoutError:
            break
        m = re.search(r"READY=1[\s\S]*listening on [\d.]+:(\d+)", msg)
        if m:
            threading.Thread(target=_drain, args=(rx,), daemon=True).start()
            return proc, int(m.group(1)), rx
    proc.kill()
    proc.wait(10)
    rx.close()
    raise AssertionError("service not ready: " + (tmp / "serve.log").read_text()[-3000:])
