"""The periodic drift check: every `period_s` while no job runs, never during one; stopping
it ends its thread. Counted in events, not in seconds, so a loaded machine only slows it."""

from __future__ import annotations

import itertools
import threading
import time
from pathlib import Path
from types import SimpleNamespace

from omnisort_hw.cell.watchdog import DriftWatchdog, WatchdogPorts
from omnisort_hw.config.watchdog import WatchdogConfig

PERIOD_S = 0.2
WAIT_S = 60.0  # the bound of every wait below; a check comes every PERIOD_S when idle


def _unused() -> None:
    raise AssertionError("the periodic check is replaced in this test")


def test_periodic_checks_wait_for_jobs(tmp_path: Path) -> None:
    store = SimpleNamespace(state_dir=tmp_path)
    ports = WatchdogPorts(store, _unused, _unused, _unused)  # type: ignore[arg-type]
    dog = DriftWatchdog(ports, WatchdogConfig(period_s=PERIOD_S))
    calls: list[float] = []
    seen = threading.Condition()
    busy = threading.Event()

    def fake_check(image: str | None = None) -> dict[str, object]:
        with seen:
            calls.append(time.monotonic())
            seen.notify_all()
        return {}

    dog.check = fake_check  # type: ignore[method-assign]
    dog.busy = busy.is_set
    dog.start()
    try:
        with seen:
            assert seen.wait_for(lambda: len(calls) >= 3, WAIT_S), calls
        busy.set()
        with seen:
            at_job_start = len(calls)
        # During the job: let the loop pass its period many times over (it polls busy() each
        # time); at most the one check already under way when the job started may land.
        loops = 10
        deadline = time.monotonic() + WAIT_S
        while loops and time.monotonic() < deadline:
            time.sleep(PERIOD_S)
            loops -= 1
        with seen:
            during_job = len(calls) - at_job_start
        busy.clear()
        with seen:
            assert seen.wait_for(lambda: len(calls) >= at_job_start + during_job + 1, WAIT_S)
    finally:
        dog.stop()
    assert dog._thread is None
    assert during_job <= 1
    # Idle checks are spaced by the period, never closer (the loop waits a full period).
    gaps = [b - a for a, b in itertools.pairwise(calls)]
    assert min(gaps) >= PERIOD_S * 0.9, gaps
