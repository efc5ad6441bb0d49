"""The Simulator tab on the commissioned virtual cell (`simulator_flow`): a knock caught by the
drift watchdog within its period (which the cell file sets), the camera mounted at 5 deg, a
cube, the target and the tool moved. It leaves the camera turned and the drift found: the
group's later modules do not move the arm."""

from __future__ import annotations

import pytest

from tests.ui import simulator_flow
from tests.ui.commissioned.shared import PERIOD_S, Commissioned

pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]


def test_the_simulator_tab_moves_the_commissioned_cell(commissioned: Commissioned) -> None:
    c = commissioned
    simulated = simulator_flow.in_simulator_tab(c.vc, c.page, c.svc.port, PERIOD_S, c.tmp)
    simulator_flow.check(simulated)
