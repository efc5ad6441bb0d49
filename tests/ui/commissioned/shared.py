"""What the package's modules share: the commissioned cell's record and the cell file's
settings (the fixture is in conftest.py; tests/conftest.py's SHARED_GROUPS sends the package to
one worker whole)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from omnisort_hw.service.launch import ServiceProcess
from sim_backend.virtual_cell.launcher import VirtualCellProcess
from tests.ui.browser_page import Page
from tests.ui.commissioning_flow import Laps

WIDTH = 960  # the demo's size: the target's markers and the floor board need it
PERIOD_S = 10.0  # the drift watchdog's period in this cell file
# Views for the intrinsics: six of the held board's poses, as the real-driver end-to-end test
# takes (the same path as the demo's ten, four views fewer; `benchmarks/` commissions with ten).
VIEWS = 6


@dataclass
class CellPage:
    """The virtual cell, its service, the page, the folder, and the steps' wall times."""

    vc: VirtualCellProcess
    svc: ServiceProcess
    page: Page
    tmp: Path
    laps: Laps


@dataclass
class Commissioned:
    """The commissioned cell: its virtual cell, service, page, folder, each step's wall time
    and the virtual cell's truth right after the commissioning."""

    vc: VirtualCellProcess
    svc: ServiceProcess
    page: Page
    tmp: Path
    times: dict[str, float]
    truth: dict[str, Any]
