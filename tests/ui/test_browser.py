"""The operator interface in a real headless browser (Debian's Chromium through chromedriver)
against `omnisort ui` and a real `omnisort serve` on the simulated cell, each its own process
on loopback, the arm paced to the wall clock. An operator: a wrong token is refused, the right
one signs in; an out-of-range value is refused before anything is sent; a sort starts after
its confirmation and its per-pick log fills; Stop ends it mid-sort and the service's status
confirms the arm stopped; a resumed sort puts every remaining cube in its bin.

The screenshots of docs/images/ui_*.png are written here (`make screenshots`)."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from omnisort_hw.service.launch import ServiceProcess
from tests.ui.browser_page import UI_S, Page, served_page, service_status, wait_for
from tests.ui.ui_procs import TOKEN, sim_cell_file

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]


@pytest.fixture()
def cell(tmp_path: Path) -> Iterator[tuple[ServiceProcess, Page]]:
    with served_page(sim_cell_file(tmp_path), tmp_path, sign_in=False) as served:
        yield served


def test_operator_sorts_stops_and_resumes_in_a_real_browser(
    cell: tuple[ServiceProcess, Page],
) -> None:
    svc, page = cell
    page.shot("ui_read_only")
    assert not page.visible("start-sort"), "a read-only page offers the sort"

    # A wrong token: refused by the service, the session stays read-only.
    page.type("token", "not-the-token")
    page.click("sign-in")
    wait_for("the refusal", lambda: "wrong token" in page.text("message"), UI_S)
    assert "Read-only" in page.text("signed")
    # The service's error count says what it is made of: by code, and the last one.
    errors = wait_for(
        "the errors row",
        lambda: "last, " in (t := page.text("status-rows")) and t,
        UI_S,
    )
    assert "unauthorized 1" in errors and "unauthorized: " in errors, errors

    page.type("token", TOKEN)
    page.click("sign-in")
    wait_for("the sign-in", lambda: page.text("signed") == "Signed in as operator", UI_S)
    wait_for("the sort form", lambda: page.visible("start-sort"), UI_S)

    # The live view, with the laser points of a map and the cubes of a location drawn on it.
    wait_for("a live picture", lambda: page.text("view-note").startswith("picture"), UI_S)
    wait_for("the operator's view controls", lambda: page.visible("map"), UI_S)
    page.click("map")
    wait_for("the map", lambda: "map done" in page.text("job-end"), 60)
    page.click("locate")
    wait_for("the location", lambda: "locate done" in page.text("job-end"), 60)
    legend = wait_for(
        "the overlays",
        lambda: "cubes" in page.text("view-legend") and page.text("view-legend"),
        UI_S,
    )
    dots = page.count("live-view", "svg circle")
    rings = page.count("live-view", "svg polygon")
    assert dots >= 50, (dots, legend)
    assert rings == 2 * int(legend.split("; ")[1].split()[0]), (rings, legend)
    width = page.d.execute_script(
        "return document.querySelector('[data-test=live-view] img').naturalWidth"
    )
    assert width == 320, width  # the simulated camera's frames, at most [ui] view_width_px

    # Out of range: the schema refuses it here, nothing reaches the service. (Start is offered
    # once the page has the service's idle state after the location: a click on it while it
    # is still disabled does nothing, as it should.)
    wait_for("Start enabled", lambda: page.el("start-sort").is_enabled(), UI_S, 0.1)
    before = service_status(svc.port)["service"]
    page.type("sort-max_objects", "0")
    page.click("start-sort")
    wait_for("the schema's refusal", lambda: "minimum of 1" in page.text("sort-problems"), UI_S)
    assert not page.visible("confirm"), "an invalid sort was offered for confirmation"
    st = service_status(svc.port)
    assert st["last_run"]["job"] == "locate", "an invalid sort reached the service"
    assert st["service"]["errors"] == before["errors"], "the service refused something sent"
    page.shot("ui_bad_input")
    # Not a number: named as typed, not read as an empty field (which would sort every cube).
    page.type("sort-max_objects", "abc")
    page.click("start-sort")
    wait_for(
        "the refusal of abc", lambda: "'abc' is not of type" in page.text("sort-problems"), UI_S
    )
    assert not page.visible("confirm"), "a sort of every cube was offered for 'abc'"
    # A colour with no bin: refused by the service before anything moves, and the page's
    # "sort started" goes once the refusal is shown.
    page.type("sort-max_objects", "")
    page.type("sort-colors", "purple")
    page.click("start-sort")
    page.confirm()
    refused = wait_for(
        "the refusal of purple",
        lambda: "no bin for purple" in (t := page.text("job-end")) and t,
        UI_S,
    )
    assert "bad_input" in refused, refused
    wait_for("the stale message gone", lambda: "started" not in page.text("message"), UI_S)
    assert service_status(svc.port)["last_run"]["job"] != "sort" or not [
        ev for ev in service_status(svc.port)["last_run"]["progress"] if "cube" in ev
    ], "a cube was picked for a colour with no bin"
    page.type("sort-colors", "")

    # Sort every cube: confirmed, then watched until the first pick is logged.
    page.type("sort-max_objects", "")
    page.click("start-sort")
    page.confirm()
    wait_for("the sort to start", lambda: service_status(svc.port)["state"] == "sorting", UI_S)
    rows = wait_for("the first pick in the log", page.pick_rows, 120, 0.25)
    assert rows[0][:2] == ["1", "1"] and rows[0][5] == "sorted", rows
    wait_for("the picks per minute", lambda: "picks/min" in page.text("picks-per-min"), UI_S)
    page.shot("ui_cell")

    # Stop mid-sort: the service says stopped, no job, and the arm stands still.
    page.click("stop")
    st = wait_for(
        "the stopped state",
        lambda: (s := service_status(svc.port))["state"] == "stopped" and s["job"] is None and s,
        UI_S,
    )
    # The devices' part of a status is a snapshot (its age in `status_age_s`): compare two
    # taken after the stop, at least a second apart (each read until its snapshot is).
    stopped_at = time.monotonic()

    def taken_after(t0: float) -> Callable[[], dict[str, Any] | None]:
        def read() -> dict[str, Any] | None:
            asked = time.monotonic()
            s = service_status(svc.port)
            return s if s.get("status_age_s", 0.0) < asked - t0 else None

        return read

    first = wait_for("a snapshot taken after the stop", taken_after(stopped_at), UI_S)
    again = wait_for("a snapshot a second later", taken_after(time.monotonic() + 1.0), UI_S)
    before, after = first["devices"]["arm"]["joints_deg"], again["devices"]["arm"]["joints_deg"]
    assert max(abs(a - b) for a, b in zip(before, after, strict=True)) < 1e-6, (before, after)
    assert again["state"] == "stopped" and again["job"] is None
    wait_for("the job's end", lambda: "stopped" in page.text("job-end"), UI_S)
    first_run = st["last_run"]
    sorted_first = sum(1 for ev in first_run["progress"] if ev.get("status") == "sorted")
    located = next(ev["to_pick"] for ev in first_run["progress"] if "to_pick" in ev)
    assert 1 <= sorted_first < located, (sorted_first, located)
    wait_for("the state on the page", lambda: page.text("state") == "stopped", UI_S)
    page.shot("ui_stopped")

    # Resume: the remaining cubes, each into its bin.
    page.click("start-sort")
    page.confirm()
    wait_for("the resumed sort's end", lambda: "sort done" in page.text("job-end"), 240, 0.5)
    final = service_status(svc.port)
    assert final["state"] == "idle", final["state"]
    outcomes = [ev["status"] for ev in final["last_run"]["progress"] if "cube" in ev]
    assert outcomes and all(o == "sorted" for o in outcomes), outcomes
    assert sorted_first + len(outcomes) == located, (sorted_first, outcomes, located)
    assert "0 skipped, 0 failed" in page.text("job-end"), page.text("job-end")
    # The pick log keeps the stopped sort's picks and numbers on through the resumed one.
    log = wait_for(
        "both sorts in the log", lambda: len(r := page.pick_rows()) == located and r, UI_S
    )
    assert [r[0] for r in log] == [str(n) for n in range(1, located + 1)], log
    assert [r[1] for r in log] == ["1"] * sorted_first + ["2"] * len(outcomes), log

    # E-stop latches the cell in fault, and Start is not offered; Reset (an operator's) takes
    # it back to idle, and Start is offered again.
    page.click("estop")
    wait_for("the fault on the page", lambda: page.text("state") == "fault", UI_S)
    assert service_status(svc.port)["state"] == "fault"
    wait_for("Start disabled", lambda: not page.el("start-sort").is_enabled(), UI_S, 0.1)
    page.click("reset")
    wait_for("idle on the page", lambda: page.text("state") == "idle", UI_S)
    assert service_status(svc.port)["state"] == "idle"
    assert "reset: the cell left" in page.text("message"), page.text("message")
    wait_for("Start enabled", lambda: page.el("start-sort").is_enabled(), UI_S, 0.1)
