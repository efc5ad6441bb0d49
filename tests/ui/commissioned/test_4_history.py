"""Going back to a kept calibration from the Commission tab of the commissioned virtual cell:
the system calibration from before the registration is current again (after the
confirmation), so the robot must be registered again before a sort."""

from __future__ import annotations

import pytest

from tests.ui.browser_page import UI_S, service_status, wait_for
from tests.ui.commissioned.shared import Commissioned

pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]


def test_a_kept_system_calibration_is_current_again(commissioned: Commissioned) -> None:
    page = commissioned.page
    page.click("tab-commission")
    page.click("to-history")
    wait_for(
        "the versions",
        lambda: page.visible("history-system") and "(current)" in page.text("history-system"),
        UI_S,
    )
    page.click("history-restore-system")
    page.confirm()
    back = wait_for(
        "the restore",
        lambda: (t := page.text("history-note")).startswith(("system.json is now", "FAIL")) and t,
        60,
        0.5,
    )
    page.shot("commission_history", at="history-system")
    status = service_status(commissioned.svc.port)
    assert back.startswith("system.json is now") and "/history/system.json." in back, back
    assert status["calibration"]["files"]["system"]["health"] == "ok", status["calibration"]
    assert not status["calibration"]["robot_registered"]
