"""After a bump, in a real headless browser: the simulated cell's stored calibration is knocked
(its camera rotation turned 0.3 deg, as a knock turns the camera away from what was calibrated)
and the operator takes the page's recovery path to a sorted cell. The sort is refused with the
drift's angle, the banner shows it, the guided steps calibrate the camera and the laser plane
(parameters with their sigmas, the residual picture), register the robot, check, and the next
sort puts a cube in its bin. 960 px: the target's markers and the floor board need it."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from omnisort_hw.config.cell import load_cell_config
from omnisort_hw.service.launch import ServiceProcess
from tests.ui.browser_page import UI_S, Page, served_page, service_status, wait_for
from tests.ui.commissioning_flow import calibrated_extrinsics
from tests.ui.ui_procs import (
    knock_calibration,
    sim_cell_file,
)

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

KNOCK_DEG = 0.3


@pytest.fixture()
def knocked(tmp_path: Path) -> Iterator[tuple[ServiceProcess, Page, Path]]:
    config = sim_cell_file(tmp_path, width=960, realtime=False, view_period_s=2.0)
    knock_calibration(config, KNOCK_DEG, (0.0, 1.0, 0.0))
    with served_page(config, tmp_path) as (svc, page):
        yield svc, page, config


def calibrated(page: Page, separation_mm: float | None, expected: bool = False) -> str:
    """The recovery's calibration with this wall separation typed (None: the cell file's);
    `expected`: its running time shown against the last one's."""
    step = ("calib-separation", "calibrate", "calib-note")
    return calibrated_extrinsics(page, separation_mm, step, expected)


def test_recovery_after_a_bump_to_a_sorted_cell(
    knocked: tuple[ServiceProcess, Page, Path], tmp_path: Path
) -> None:
    svc, page, config = knocked
    page.click("start-sort")
    page.confirm()
    refused = wait_for(
        "the refusal",
        lambda: "calibration_drift" in page.text("job-end") and page.text("job-end"),
        120,
        0.5,
    )
    assert "turned" in refused, refused
    alarm = wait_for("the drift banner", lambda: page.visible("drift") and page.text("drift"), UI_S)
    # Motion refused: Start sort is not offered until the recovery.
    wait_for("Start disabled", lambda: not page.el("start-sort").is_enabled(), UI_S, 0.1)
    angle = float(alarm.split("camera turned ")[1].split(" deg")[0])
    assert abs(angle - KNOCK_DEG) < 0.1, alarm  # the board's measure of the knock
    assert service_status(svc.port)["last_run"]["job"] != "sort" or not [
        ev for ev in service_status(svc.port)["last_run"]["progress"] if "cube" in ev
    ], "a cube was picked on the knocked calibration"
    page.shot("ui_drift")

    # Acknowledge asks first: Cancel sends nothing and motion stays refused. Accepted, motion
    # is allowed again on the operator's word (the picks checked by hand): the banner goes,
    # until the next check (the sort's own, first) measures the camera turned again.
    page.click("acknowledge")
    wait_for("the question", lambda: page.visible("cancel"), UI_S)
    page.click("cancel")
    wait_for("the question gone", lambda: not page.visible("cancel"), UI_S)
    st = service_status(svc.port)
    assert st["drift"]["motion_refused"] and st["drift"]["acknowledged"] is None, st["drift"]
    page.click("acknowledge")
    page.confirm()
    wait_for(
        "the acknowledgement",
        lambda: page.text("message") == "drift acknowledged: motion allowed again",
        UI_S,
    )
    st = service_status(svc.port)
    assert not st["drift"]["motion_refused"] and st["drift"]["acknowledged"], st["drift"]
    wait_for("the banner gone", lambda: not page.visible("drift"), UI_S)
    wait_for("Start enabled", lambda: page.el("start-sort").is_enabled(), UI_S, 0.1)
    page.click("start-sort")
    page.confirm()
    wait_for("the banner again", lambda: page.visible("drift"), 120, 0.5)
    st = service_status(svc.port)
    assert st["drift"]["motion_refused"] and st["drift"]["acknowledged"] is None, st["drift"]
    assert not [ev for ev in st["last_run"]["progress"] if "cube" in ev], "picked when knocked"

    # The simulated cell's laser is on from the start (the drift check leaves it so): off,
    # to see the page say why the target is not found.
    page.click("laser-off")
    wait_for("the laser off", lambda: page.text("message") == "laser off", UI_S, 0.2)
    page.click("recover")
    wait_for("the recovery", lambda: page.visible("placed"), UI_S)
    # The target's detection, drawn live: without the laser, why not and the markers seen;
    # with it, the whole target.
    dark = wait_for("a detection", lambda: page.text("recovery-target-summary"), UI_S, 0.5)
    assert "not found" in dark and "laser" in dark, dark
    page.click("recovery-laser")
    wait_for(
        "the target found",
        lambda: page.text("recovery-target-summary").startswith("the two-sided target found"),
        UI_S,
        0.5,
    )
    # Eight markers ringed, and the borders, floor lines and stripe as dots.
    assert page.count("recovery-target-image", "svg circle[fill=none]") == 8
    assert page.count("recovery-target-image", "svg circle") > 200
    page.shot("ui_recovery_target", at="recovery")
    page.click("placed")
    wait_for("the calibration step", lambda: page.visible("calibrate"), UI_S)

    # A wall separation typed 1 % wrong: a WARN of the scale check, which only its explicit
    # acceptance takes on, logged; taken, then retaken. (A FAIL, which nothing accepts, is the
    # same guided step's: tested on the commissioned cell, tests/ui/commissioned.)
    separation = load_cell_config(config).target.separation_mm
    assert separation is not None
    note = calibrated(page, 1.01 * separation)
    assert note.startswith("WARN") and "floor board's scale" in note, note
    assert not page.visible("accept-calib") and page.visible("accept-calib-warn")
    page.click("accept-calib-warn")
    wait_for("the registration step", lambda: page.visible("register"), UI_S)
    logged = (tmp_path / "ui.log").read_text()
    assert "recovery: camera and laser plane accepted with warning" in logged, logged[-2000:]
    page.click("back-to-calib")
    # The retake says how long the first calibration took here while it runs.
    note = calibrated(page, None, expected=True)
    assert note.startswith("PASS"), note
    assert page.visible("accept-calib") and not page.visible("accept-calib-warn")
    rows = page.el("calib-params").text
    for name in ("cam_roll_deg", "cam_pitch_deg", "laser_distance_mm"):
        assert name in rows, rows
    shown = wait_for(
        "the residual picture",
        lambda: page.d.execute_script(
            "return document.querySelector('[data-test=calib-picture] img')?.naturalWidth || 0"
        ),
        UI_S,
    )
    assert shown >= 400, shown
    page.shot("ui_recalibration")
    page.click("accept-calib")

    wait_for("the registration step", lambda: page.visible("register"), UI_S)
    page.click("register")
    wait_for("the registration", lambda: page.visible("accept-register"), 120, 0.5)
    assert page.text("register-note").startswith("PASS"), page.text("register-note")
    page.click("accept-register")
    wait_for("the check step", lambda: page.visible("check"), UI_S)
    page.click("check")
    wait_for("the check", lambda: page.visible("recovery-done"), 120, 0.5)
    checked = page.text("check-note")
    assert checked.startswith("PASS") and "no drift" in checked, checked
    st = service_status(svc.port)
    assert not st["drift"]["motion_refused"] and st["motion_allowed"], st["drift"]
    wait_for("the banner gone", lambda: not page.visible("drift"), UI_S)
    page.click("recovery-done")

    wait_for("Start enabled", lambda: page.el("start-sort").is_enabled(), UI_S, 0.1)
    # One cube is the recovered calibration's proof: its pick lands in its bin (every bin is
    # reached by the commissioned cell's sort, tests/ui/commissioned).
    page.type("sort-max_objects", "1")
    page.click("start-sort")
    page.confirm()
    wait_for("the sort", lambda: "sort done" in page.text("job-end"), 240, 0.5)
    end = page.text("job-end")
    assert "sort done: 1 sorted," in end and " 0 failed" in end, end
    outcomes = [
        ev["status"] for ev in service_status(svc.port)["last_run"]["progress"] if "cube" in ev
    ]
    assert outcomes == ["sorted"], outcomes
    page.shot("ui_recovered")
