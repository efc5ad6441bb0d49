"""Fixtures: a service with in-memory devices running in a thread on a loopback port."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from omnisort_hw.cell.cell import Cell, CellDevices
from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.service.client import Client
from omnisort_hw.service.server import RunningService, Service, start_in_thread
from tests.service.fakes import Journal, make_cell

TOKEN = "test-token-0123456789"


@dataclass
class Harness:
    running: RunningService
    cell: Cell
    devices: CellDevices
    journal: Journal
    log_dir: Path

    def client(self, token: str | None = None, timeout_s: float = 10.0) -> Client:
        return Client(self.running.host, self.running.port, token=token, timeout_s=timeout_s)


@pytest.fixture
def make_service(tmp_path: Path) -> Iterator[Callable[..., Harness]]:
    started: list[Harness] = []

    def factory(
        token: str | None = None,
        move_seconds: float = 0.5,
        calibrated: bool = True,
        **config: object,
    ) -> Harness:
        n = len(started)
        log_dir = tmp_path / f"logs{n}"
        cell, devices, journal = make_cell(
            tmp_path / f"state{n}", log_dir, move_seconds=move_seconds, calibrated=calibrated
        )
        cfg = ServiceConfig(port=0, token=token, **config)  # type: ignore[arg-type]
        h = Harness(start_in_thread(Service(cell, cfg)), cell, devices, journal, log_dir)
        started.append(h)
        return h

    yield factory
    for h in started:
        h.running.stop()


@pytest.fixture
def service(make_service: Callable[..., Harness]) -> Harness:
    return make_service()
