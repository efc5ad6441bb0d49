"""One virtual cell commissioned from nothing through the page alone, shared by this package's
modules: `omnisort serve` on the real drivers (the virtual cell's MJPEG camera, Modbus laser
and UR controller), no calibration at all, `omnisort ui` and headless Chromium, and the
operator's commissioning steps (`commissioning_flow`). The package is one of
tests/conftest.py's SHARED_GROUPS, so one worker builds the cell once and runs the modules in
their order: the intrinsics from the views, the rest of the commissioning, the sort, the
Simulator tab's checks (which knock and turn the camera), then going back to a kept
calibration."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from omnisort_hw.config.cell import load_cell_config
from tests.sim.virtual_cell_fixture import virtual_cell
from tests.ui import commissioning_flow as flow
from tests.ui.browser_page import served_page
from tests.ui.commissioned.shared import PERIOD_S, VIEWS, WIDTH, CellPage, Commissioned


@pytest.fixture(scope="session")
def cell_page(tmp_path_factory: pytest.TempPathFactory) -> Iterator[CellPage]:
    """The virtual cell with no calibration, its service, the interface and the page."""
    pytest.importorskip("pybullet", reason="the virtual cell needs pybullet")
    tmp = tmp_path_factory.mktemp("commissioned")
    with virtual_cell("sorting", width=WIDTH, unlock_delay_s=5.0) as vc:
        config = flow.virtual_cell_file(vc, tmp, watchdog_period_s=PERIOD_S)
        with served_page(config, tmp) as (svc, page):
            yield CellPage(vc, svc, page, tmp, flow.Laps())


@pytest.fixture(scope="session")
def intrinsics_from_views(cell_page: CellPage) -> CellPage:
    """The Commission tab's first step done: the views and the intrinsics."""
    flow.views_in_page(cell_page.page, cell_page.laps, views=VIEWS)
    return cell_page


@pytest.fixture(scope="session")
def commissioned(intrinsics_from_views: CellPage) -> Commissioned:
    """Every step of the Commission tab done, to the verification's verdict."""
    c = intrinsics_from_views
    # A separation typed 3 % wrong first: the scale check's FAIL, which nothing accepts.
    separation = load_cell_config(c.tmp / "cell.toml").target.separation_mm
    assert separation is not None
    flow.rest_in_page(c.page, c.laps, wrong_separation_mm=1.03 * separation)
    return Commissioned(c.vc, c.svc, c.page, c.tmp, c.laps.total(), c.vc.truth())
