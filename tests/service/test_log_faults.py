"""A watchdog that means health: pings go on through a failed log roll, the failure is in
`status` and the log, the service keeps working (run log off, stderr only) and recovers; the
`.rrd` size limit holds during a job; a deleted log directory is noticed."""

from __future__ import annotations

import shutil
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from omnisort_hw.cell.rrd import RunLogRotator, rrd_files
from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.runlog import entity_paths
from omnisort_hw.service.server import Service, start_in_thread
from omnisort_hw.service.systemd import Notifier
from tests.service.fakes import make_cell

pytestmark = pytest.mark.timeout(120)

WATCHDOG_S = 1.0  # WatchdogSec of the test; systemd kills after this long without a ping
CHECK_S = 0.1


class _Pings:
    """Receives sd_notify datagrams and records when each WATCHDOG=1 arrived."""

    def __init__(self, path: Path) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(str(path))
        self.sock.settimeout(0.2)
        self.times: list[float] = []
        self.messages: list[str] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                msg = self.sock.recv(4096).decode()
            except TimeoutError:
                continue
            self.messages.append(msg)
            if "WATCHDOG=1" in msg:
                self.times.append(time.monotonic())

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        self.sock.close()

    def max_gap(self, since: float) -> float:
        t = [since, *[x for x in self.times if x >= since], time.monotonic()]
        return max(np.diff(t))


def _wait(pred, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not pred():
        assert time.monotonic() < deadline, "condition not met in time"
        time.sleep(0.02)


def test_pings_continue_through_a_failed_log_roll(tmp_path: Path) -> None:
    log_dir = tmp_path / "logs"
    cell, _, _ = make_cell(tmp_path / "state", log_dir, move_seconds=2.0)
    pings = _Pings(tmp_path / "notify.sock")
    env = {
        "NOTIFY_SOCKET": str(tmp_path / "notify.sock"),
        "WATCHDOG_USEC": str(int(WATCHDOG_S * 1e6)),
    }
    service = Service(cell, ServiceConfig(port=0), Notifier(env))
    service.log_check_s = CHECK_S
    running = start_in_thread(service)
    try:
        from omnisort_hw.service.client import Client

        with Client(running.host, running.port) as c:
            first = c.call("status")["result"]["logging"]
            assert first["ok"] and Path(first["rrd"]).parent == log_dir
            # The log directory is replaced by a file: every roll from now on fails.
            t_fail = time.monotonic()
            shutil.rmtree(log_dir)
            log_dir.write_text("not a directory\n")
            _wait(lambda: not c.call("status")["result"]["logging"]["ok"])
            st = c.call("status")["result"]
            assert str(log_dir) in st["logging"]["problem"] and st["rrd"] is None
            moved = c.call("move", {"joints_deg": [5, 0, 0, 0, 0, 0]}, timeout_s=20)
            assert moved["ok"], moved
            time.sleep(3 * WATCHDOG_S)
            gap = pings.max_gap(t_fail)
            # The directory comes back: the run log resumes in a new file there.
            log_dir.unlink()
            log_dir.mkdir()
            _wait(lambda: c.call("status")["result"]["logging"]["ok"])
            back = c.call("status")["result"]
        assert Path(back["rrd"]).parent == log_dir and Path(back["rrd"]).exists()
    finally:
        running.stop()
        pings.close()
    assert gap < WATCHDOG_S, f"{gap:.2f} s without a watchdog ping"
    assert any("run log unavailable" in m for m in pings.messages)


def test_deleted_log_dir_is_noticed_and_recreated(tmp_path: Path) -> None:
    log_dir = tmp_path / "logs"
    rot = RunLogRotator(log_dir, keep=5)
    first = rot.path
    shutil.rmtree(log_dir)
    assert rot.check()
    assert rot.path is not None and rot.path != first and rot.path.parent == log_dir
    rot.log.event("service/state", "after")
    rot.close()
    assert "/service/state" in entity_paths(rot.path)
    assert rot.health().ok


def test_rrd_size_limits_hold_while_one_job_keeps_logging(tmp_path: Path) -> None:
    """Per file and in all, checked after every entry (the service checks every second; each
    entry here is under the 10 % headroom left below the file limit)."""
    limit, total_limit = 300_000, 1_200_000
    rot = RunLogRotator(tmp_path, keep=100, max_total_bytes=total_limit, max_file_bytes=limit)
    held = rot.log  # a job takes the run log once and keeps it (the sorter does)
    img = np.random.default_rng(0).integers(0, 255, (60, 60, 3), np.uint8)
    largest = total = 0
    for i in range(400):
        held.set_step("frame", i)
        held.image("camera/raw", img)
        held._rec.flush()
        rot.check()
        sizes = [p.stat().st_size for p in rrd_files(tmp_path)]
        largest, total = max(largest, *sizes), max(total, sum(sizes))
    held.image("camera/raw", img)
    rot.close()
    files = rrd_files(tmp_path)
    assert len(files) >= 3
    assert largest <= limit and total <= total_limit, (largest, total)
    assert "/camera/raw" in entity_paths(files[-1])
