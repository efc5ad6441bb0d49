"""A sort of the four cubes started from the cell tab of the commissioned virtual cell (after
the confirmation): every cube in the bin of its colour by the virtual cell's truth, nothing
collided."""

from __future__ import annotations

import pytest

from omnisort_hw.service.virtual_cell_demo import check_truth
from tests.ui.browser_page import UI_S, wait_for
from tests.ui.commissioned.shared import Commissioned

pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]


def test_the_commissioned_cell_sorts_from_the_page(commissioned: Commissioned) -> None:
    page = commissioned.page
    page.click("tab-cell")
    # Offered once the page has the cell idle after the verification's location (a click on
    # a disabled Start does nothing).
    wait_for("Start enabled", lambda: page.el("start-sort").is_enabled(), UI_S, 0.1)
    page.click("start-sort")
    page.confirm()
    end = wait_for(
        "the sort's end",
        lambda: ((t := page.text("job-end")).startswith("sort:") or "sort done" in t) and t,
        600,
        1.0,
    )
    page.shot("commission_sorted")
    truth = commissioned.vc.truth()
    assert "4 sorted, 0 skipped, 0 failed" in end, end
    assert check_truth(truth) == [], check_truth(truth)
