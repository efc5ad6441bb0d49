"""The page's one timer (`BrowserSession.tick`): each panel's refresh runs at its own period, in
the order they asked; the timer ticks at the shortest period asked; a job's end makes every
refresh due at the next tick."""

from __future__ import annotations

from types import SimpleNamespace
from typing import cast

import pytest

from omnisort_hw.ui import session as session_module
from omnisort_hw.ui.context import UiContext
from omnisort_hw.ui.session import BrowserSession


@pytest.fixture()
def clock(monkeypatch: pytest.MonkeyPatch) -> list[float]:
    """The session's clock, moved by the test (s)."""
    now = [100.0]
    monkeypatch.setattr(session_module.time, "monotonic", lambda: now[0])
    return now


def session_without_service() -> BrowserSession:
    """A session whose timer runs with no service: of its context, only the jobs' count."""
    return BrowserSession(cast(UiContext, SimpleNamespace(jobs=SimpleNamespace(ended=0))), "b")


def test_each_refresh_runs_at_its_own_period(clock: list[float]) -> None:
    s, ran = session_without_service(), []
    s.every(1.0, lambda: ran.append("status"))
    s.every(0.5, lambda: ran.append("view"))
    s.every(0.25, lambda: ran.append("fast"))
    assert s.tick_s == 0.25  # the shortest period asked
    for _ in range(8):  # two seconds of ticks
        s.tick()
        clock[0] += s.tick_s
    assert ran.count("status") == 2 and ran.count("view") == 4 and ran.count("fast") == 8
    assert ran[:3] == ["status", "view", "fast"]  # the order they asked


def test_a_jobs_end_makes_every_refresh_due_at_the_next_tick(clock: list[float]) -> None:
    s, ran = session_without_service(), []
    s.every(0.25, lambda: ran.append("status"))
    s.every(0.5, lambda: ran.append("step"))
    s.tick()  # both run first, then each at its period
    clock[0] += 0.25
    s.tick()
    assert ran == ["status", "step", "status"]  # the step is due only in another 0.25 s
    s.ctx.jobs.ended += 1  # type: ignore[attr-defined]  # a job of this interface ended
    clock[0] += 0.01
    s.tick()
    assert ran[3:] == ["status", "step"], ran  # both at once, the step not a period later
    clock[0] += 0.01
    s.tick()
    assert ran[5:] == [], ran  # and then at their periods again
