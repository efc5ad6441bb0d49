"""Start the fake-device service (`fake_service.py`) as a subprocess for end-to-end tests."""

from __future__ import annotations

import os
import subprocess
import sys
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


def process_gone(pid: int, within_s: float = 10.0) -> bool:
    """True once no process `pid` exists (ended and reaped), waiting at most `within_s`."""
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.02)
    return False
