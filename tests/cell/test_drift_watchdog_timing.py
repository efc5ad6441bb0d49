"""The periodic drift check: every `period_s` while no job runs, never during one; stopping
it ends its thread."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from types import SimpleNamespace

from omnisort_hw.cell.watchdog import DriftWatchdog
from omnisort_hw.config.watchdog import WatchdogConfig


def test_periodic_checks_wait_for_jobs(tmp_path: Path) -> None:
    cell = SimpleNamespace(store=SimpleNamespace(state_dir=tmp_path))
    dog = DriftWatchdog(cell, WatchdogConfig(period_s=0.2))  # type: ignore[arg-type]
    calls: list[float] = []
    busy = threading.Event()
    dog.check = lambda image=None: calls.append(time.monotonic()) or {}  # type: ignore[method-assign]
    dog.busy = busy.is_set
    dog.start()
    try:
        time.sleep(3.5)
        idle_calls = len(calls)
        busy.set()
        time.sleep(2.5)
        during_job = len(calls) - idle_calls
    finally:
        dog.stop()
    assert dog._thread is None
    # 3.5 s of idle at 0.2 s: 17 checks, fewer when this machine is loaded, never more.
    assert 8 <= idle_calls <= 18
    assert during_job <= 1  # one may have been under way when the job started
