"""The virtual cell commissioned from nothing, two ways, for the browser test and the
benchmark: through the pages alone (`in_page`: the board for the intrinsics' views held from
the Simulator tab, every step in the Commission tab), and through `omnisort ctl` for the same
steps (`with_ctl`, the board held through the virtual cell's control channel). Each returns
the wall time of each step."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw.core.frames import rotation_angle_deg
from sim_backend.virtual_cell.cell import CONTROL_PORT
from sim_backend.virtual_cell.cell_file import cell_file_text
from sim_backend.virtual_cell.held_board import HELD_SQUARE_MM
from sim_backend.virtual_cell.launcher import VirtualCellProcess
from tests.service.sim_cell import brisk_sort
from tests.ui.browser_page import UI_S, Page, wait_for
from tests.ui.ui_procs import PROJECT_ROOT, TOKEN

VIEWS = 10  # of the held board's poses: the demo's number of intrinsics views
STEP_TIMEOUT_S = 300.0


def virtual_cell_file(vc: VirtualCellProcess, tmp: Path, watchdog_period_s: float = 0.0) -> Path:
    """The cell file of `vc` with no calibration yet, the tests' token, a brisk sort (its moves
    at `sim_cell.FAST_MOVES`), a brisk page with the Simulator tab on the cell's control
    channel, and the drift watchdog's period (0: off)."""
    config = tmp / "cell.toml"
    config.write_text(
        cell_file_text(vc.host, state_dir="state", log_dir="logs")
        + f'\n[service]\ntoken = "{TOKEN}"\n\n[ui]\nstatus_period_s = 0.25\n'
        f'view_period_s = 0.5\nsim_control = "{vc.host}:{CONTROL_PORT}"\n'
        f"\n[watchdog]\nperiod_s = {watchdog_period_s}\n"
    )
    brisk_sort(config)
    return config


class Laps:
    """Each step's wall time (s) from the end of the one before (or a restart: time spent
    between steps is not a step's), and the total from the start."""

    def __init__(self) -> None:
        self.start = self.mark = time.monotonic()
        self.times: dict[str, float] = {}

    def lap(self, step: str) -> None:
        now = time.monotonic()
        self.times[step] = round(now - self.mark, 1)
        self.mark = now

    def restart(self) -> None:
        self.mark = time.monotonic()

    def total(self) -> dict[str, float]:
        return {**self.times, "total": round(time.monotonic() - self.start, 1)}


def _step_passed(page: Page, note: str, timeout_s: float = STEP_TIMEOUT_S) -> str:
    """The step's note once its job has ended; it must not be a failure."""
    text = wait_for(
        f"the {note}",
        lambda: (t := page.text(note)) and not t.endswith("...") and t,
        timeout_s,
        0.25,
    )
    assert text.startswith(("PASS", "WARN")), text
    return str(text)


def show_tab(page: Page, tab: str, gone: str) -> None:
    """Open a tab of the page, and wait until the one before has gone (an element of it,
    `gone`, no longer shown): a click during the panels' transition can miss its button."""
    page.click(tab)
    wait_for(f"{gone} to go", lambda: not page.visible(gone), UI_S, 0.05)


def sim_note_after(page: Page, button: str, starts: str, timeout_s: float = 60.0) -> str:
    """Click a button of the Simulator tab; the panel's note once it says `starts` (on a
    time-out, the note as it stands)."""
    page.click(button)
    try:
        return str(
            wait_for(
                f"the note after {button}",
                lambda: (t := page.text("sim-note")).startswith(starts) and t,
                timeout_s,
                0.1,
            )
        )
    except AssertionError as exc:
        raise AssertionError(f"{exc}: the note says {page.text('sim-note')!r}") from None


def in_page(
    page: Page, shots: bool = True, views: int = VIEWS, first_from_simulator: bool = True
) -> dict[str, float]:
    """Commission through the Commission tab, from the tab's opening to the verification's
    verdict; the wall time of each step (s). `shots`: a screenshot of each step;
    `first_from_simulator`: the board's first pose held from the Simulator tab (else from the
    views step's own button, as the other poses are)."""
    laps = Laps()
    views_in_page(page, laps, shots, views, first_from_simulator)
    rest_in_page(page, laps, shots)
    return laps.total()


def views_in_page(
    page: Page,
    laps: Laps,
    shots: bool = True,
    views: int = VIEWS,
    first_from_simulator: bool = True,
) -> None:
    """The Commission tab's first step: the views of the board held from the Simulator tab,
    the intrinsics calibrated from them, and on to the next step (laps: views, intrinsics).
    `first_from_simulator`: the first pose held from the Simulator tab (else, as the others,
    from the step's "Next board pose")."""

    def shot(name: str, at: str) -> None:
        if shots:
            page.shot(name, at=at)

    page.click("tab-commission")
    page.type("square", f"{HELD_SQUARE_MM:g}")
    for k in range(views):
        # The board walked on to its next pose: the first from the Simulator tab, the others
        # from the views step itself (the same channel command, offered there with a
        # simulated cell).
        held = f"board held at pose {k}"
        if k == 0 and first_from_simulator:
            show_tab(page, "tab-simulator", "add-view")
            sim_note_after(page, "sim-board-next", held)
            show_tab(page, "tab-commission", "sim-board-next")
        else:
            page.click("intr-next-pose")
            wait_for(
                held, lambda held=held: page.text("intr-pose-note").startswith(held), UI_S, 0.1
            )
        page.click("add-view")
        name = f"view_{k + 1:03d}"
        wait_for(name, lambda name=name: name in page.text("views-note"), UI_S, 0.1)
        if k == views // 2:
            wait_for("the coverage", lambda: page.count("intr-detect-image", "path"), UI_S)
            shot("commission_views", "intr-detect-image")
    laps.lap("views")
    page.click("calibrate-intr")
    intrinsics = _step_passed(page, "intr-note")
    assert "cross-validated RMS" in intrinsics, intrinsics
    laps.lap("intrinsics")
    if shots:
        wait_for(
            "the report",
            lambda: page.d.execute_script(
                "return document.querySelector('[data-test=intr-uncertainty] img')"
                "?.naturalWidth || 0"
            ),
            UI_S,
        )
        time.sleep(1.0)  # the pictures fade in
        shot("commission_intrinsics", "intr-note")
    show_tab(page, "tab-simulator", "add-view")
    sim_note_after(page, "sim-board-down", "board put down")
    show_tab(page, "tab-commission", "sim-board-down")
    page.click("intr-next")
    laps.restart()


def calibrated_extrinsics(
    page: Page,
    separation_mm: float | None,
    step: tuple[str, str, str] | None = None,
    expected: bool = False,
) -> str:
    """A calibration of the camera and laser plane with this wall separation typed (None: the
    field emptied, the cell file's); its note once it has ended. `step`: the (separation field,
    button, note) of the flow, the Commission tab's by default. `expected`: while it runs, the
    step shows its running time against the last such calibration's on this cell."""
    field, button, note = step or ("extr-separation", "calibrate-extr", "extr-note")
    page.type(field, "" if separation_mm is None else f"{separation_mm:.1f}")
    page.click(button)
    wait_for("the job sent", lambda: page.text(note).endswith("..."), UI_S, 0.1)
    if expected:

        def clock() -> str:
            assert page.text(note).endswith("..."), "ended before its running time was shown"
            return page.text(f"{note}-running")

        shown = wait_for("the running time", lambda: "its last run here" in clock(), UI_S, 0.1)
        assert shown
        line = page.text(f"{note}-running")
        assert line.startswith("calibrate (request ") and " s of about " in line, line
    return str(
        wait_for(
            "the calibration",
            lambda: (t := page.text(note)) and not t.endswith("...") and t,
            STEP_TIMEOUT_S,
            0.25,
        )
    )


def rest_in_page(
    page: Page, laps: Laps, shots: bool = True, wrong_separation_mm: float | None = None
) -> None:
    """The Commission tab's steps after the intrinsics: the camera and the laser plane from
    the two-sided target, the robot registration, the verification's map and locate (laps:
    extrinsics, registration, verification). `wrong_separation_mm`: first a calibration with
    this separation typed, whose FAIL must leave no way on (not in the laps)."""

    def shot(name: str, at: str) -> None:
        if shots:
            page.shot(name, at=at)

    page.click("commission-laser")
    wait_for(
        "the target drawn",
        lambda: page.text("extr-detect-summary").startswith("the two-sided target found"),
        60,
        0.25,
    )
    shot("commission_target", "extr-detect-image")
    if wrong_separation_mm is not None:
        laps.lap("extrinsics, target")
        failed = calibrated_extrinsics(page, wrong_separation_mm)
        assert failed.startswith("FAIL") and "floor board's scale" in failed, failed
        assert not page.visible("extr-next") and not page.visible("extr-next-warn")
        page.type("extr-separation", "")
        laps.restart()
    page.click("calibrate-extr")
    _step_passed(page, "extr-note")
    assert "laser_distance_mm" in page.el("extr-params").text
    laps.lap("extrinsics")
    if shots:
        time.sleep(1.5)  # the residual picture is fetched, then fades in
    shot("commission_extrinsics", "extr-note")
    page.click("extr-next")
    laps.restart()

    wait_for(
        "the floor board drawn",
        lambda: "checkerboard found" in page.text("reg-detect-summary"),
        60,
        0.25,
    )
    page.click("commission-register")
    _step_passed(page, "reg-note")
    laps.lap("registration")
    shot("commission_registration", "reg-note")
    page.click("reg-next")
    laps.restart()

    page.click("verify-map")
    _step_passed(page, "verify-map-note")
    page.click("verify-locate")
    located = _step_passed(page, "verify-locate-note")
    assert "4 cubes located" in located, located
    wait_for("the verdict", lambda: page.text("commissioned").startswith("Commissioned"), UI_S)
    laps.lap("verification")
    shot("commission_verified", "verify-map-note")


def ctl(port: int, *words: str, timeout_s: float = STEP_TIMEOUT_S) -> dict[str, Any]:
    """`omnisort ctl --json COMMAND k=v ...` as a technician types it; its reply's result."""
    door = [sys.executable, "-m", "omnisort_hw.cli", "ctl", "--port", str(port)]
    run = subprocess.run(
        [*door, "--token", TOKEN, "--json", *words],
        capture_output=True,
        text=True,
        timeout=timeout_s,
        cwd=PROJECT_ROOT,
    )
    assert run.returncode == 0, (words, run.stdout[-2000:], run.stderr[-2000:])
    return dict(json.loads(run.stdout)["result"])


def with_ctl(vc: VirtualCellProcess, port: int, views: int = VIEWS) -> dict[str, float]:
    """The same steps through `omnisort ctl`, one command line each (a view: the board held,
    then `views action=add`); the wall time of each step (s)."""
    laps = Laps()
    folder = ""
    for k in range(views):
        vc.control("board", timeout_s=60.0, view=k)
        folder = ctl(port, "views", "action=add", "board=9x6")["folder"]
    laps.lap("views")
    ctl(port, "calibrate", "what=intrinsics", f"folder={folder}", f"square_mm={HELD_SQUARE_MM}")
    laps.lap("intrinsics")
    vc.control("board", timeout_s=60.0, view=None)
    ctl(port, "laser", "on=true")
    ctl(port, "calibrate", "what=extrinsics")
    laps.lap("extrinsics")
    ctl(port, "register_robot")
    laps.lap("registration")
    ctl(port, "map", "points=true")
    located = ctl(port, "locate")
    assert located["count"] == 4, located
    laps.lap("verification")
    return laps.total()


def calibration_errors(system_json: Path, truth: dict[str, Any]) -> dict[str, float]:
    """The stored calibration against the virtual cell's truth: the turn between the camera
    rotations and between the laser planes' normals (deg), the laser distance's error (mm)."""
    system = json.loads(system_json.read_text())

    def angle(a: np.ndarray, b: np.ndarray) -> float:
        if a.ndim == 1:  # two planes' normals, either sign
            a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
            return float(np.degrees(np.arccos(np.clip(abs(a @ b), -1.0, 1.0))))
        return float(rotation_angle_deg(a, b))

    def vec(record: dict[str, Any], *keys: str) -> np.ndarray:
        for key in keys:
            record = record[key]
        return np.asarray(record, float)

    return {
        "camera_deg": angle(
            vec(system, "camera_rotation", "matrix"), vec(truth, "camera_rotation", "matrix")
        ),
        "laser_plane_deg": angle(
            vec(system, "laser_plane", "normal"), vec(truth, "laser_plane", "normal")
        ),
        "laser_distance_mm": abs(
            system["laser_plane"]["distance_mm"] - truth["laser_plane"]["distance_mm"]
        ),
    }
