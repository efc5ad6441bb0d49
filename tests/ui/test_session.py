"""The page's one timer (`BrowserSession.tick`): each panel's refresh runs at its own period, in
the order they asked; the timer ticks at the shortest period asked."""

from __future__ import annotations

from typing import cast

import pytest

from omnisort_hw.ui import session as session_module
from omnisort_hw.ui.context import UiContext
from omnisort_hw.ui.session import BrowserSession


def test_each_refresh_runs_at_its_own_period(monkeypatch: pytest.MonkeyPatch) -> None:
    clock = [100.0]
    monkeypatch.setattr(session_module.time, "monotonic", lambda: clock[0])
    s = BrowserSession(cast(UiContext, None), "b")  # the timer needs no service
    ran: list[str] = []
    s.every(1.0, lambda: ran.append("status"))
    s.every(0.5, lambda: ran.append("view"))
    s.every(0.25, lambda: ran.append("fast"))
    assert s.tick_s == 0.25  # the shortest period asked
    for _ in range(8):  # two seconds of ticks
        s.tick()
        clock[0] += s.tick_s
    assert ran.count("status") == 2 and ran.count("view") == 4 and ran.count("fast") == 8
    assert ran[:3] == ["status", "view", "fast"]  # the order they asked
