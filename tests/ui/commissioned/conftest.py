"""One virtual cell commissioned from nothing through the page alone, shared by this package's
modules: `omnisort serve` on the real drivers (the virtual cell's MJPEG camera, Modbus laser
and UR controller), no calibration at all, `omnisort ui` and headless Chromium, and the
operator's commissioning steps (`commissioning_flow.in_page`). The package is one of
tests/conftest.py's SHARED_GROUPS, so one worker builds the cell once and runs the modules in
their order: the commissioning checked, the sort, the Simulator tab's checks (which knock and
turn the camera), then going back to a kept calibration."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.sim.virtual_cell_fixture import virtual_cell
from tests.ui import commissioning_flow as flow
from tests.ui.browser_page import served_page
from tests.ui.commissioned.shared import PERIOD_S, WIDTH, Commissioned


@pytest.fixture(scope="session")
def commissioned(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Commissioned]:
    pytest.importorskip("pybullet", reason="the virtual cell needs pybullet")
    tmp = tmp_path_factory.mktemp("commissioned")
    with virtual_cell("sorting", width=WIDTH, unlock_delay_s=5.0) as vc:
        config = flow.virtual_cell_file(vc, tmp, watchdog_period_s=PERIOD_S)
        with served_page(config, tmp) as (svc, page):
            times = flow.in_page(page)
            yield Commissioned(vc, svc, page, tmp, times, vc.truth())
