"""One instance per cell: a second `omnisort serve` of the same cell is refused before it opens
any device, with the first one's PID; the first goes on; a SIGKILLed holder does not block."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from omnisort_hw.cell.lock import InstanceLock, InstanceLockedError
from omnisort_hw.service.client import Client
from omnisort_hw.service.demo import write_config
from omnisort_hw.service.launch import start_service

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
pytestmark = pytest.mark.timeout(180)
PROJECT_ROOT = Path(__file__).resolve().parents[2]


def _serve(config: Path, port: str = "0") -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in {"NOTIFY_SOCKET", "WATCHDOG_USEC"}}
    env["PYTHONPATH"] = str(PROJECT_ROOT)
    return subprocess.run(
        [sys.executable, "-m", "omnisort_hw.cli", "serve", "--config", str(config), "--port", port],
        cwd=PROJECT_ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_second_instance_refused_with_the_holders_pid(tmp_path: Path) -> None:
    config = write_config(tmp_path, 320)
    first = start_service(config, tmp_path / "first")
    try:
        second = _serve(config)
        with Client(first.host, first.port) as c:
            st = c.call("status")["result"]
    finally:
        assert first.stop() == 0
    assert second.returncode != 0
    assert f"PID {first.proc.pid}" in second.stderr, second.stderr[-2000:]
    assert "already run by another omnisort service" in second.stderr
    assert "connecting" not in second.stderr  # no device was opened
    assert "Traceback" not in second.stderr
    assert st["state"] == "idle" and st["service"]["pid"] == first.proc.pid


def test_a_killed_holder_does_not_block_the_next(tmp_path: Path) -> None:
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time; from omnisort_hw.cell.lock import InstanceLock;"
            "InstanceLock(sys.argv[1]).acquire(); print('held', flush=True); time.sleep(60)",
            str(tmp_path),
        ],
        cwd=PROJECT_ROOT,
        env={**os.environ, "PYTHONPATH": str(PROJECT_ROOT)},
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        with pytest.raises(InstanceLockedError, match=f"PID {holder.pid}"):
            InstanceLock(tmp_path).acquire()
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait(10)
    with InstanceLock(tmp_path) as lock:
        assert lock.holder_pid() == os.getpid()
