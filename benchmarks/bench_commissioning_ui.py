"""Commissioning the virtual cell from nothing through the operator interface's pages (each of
the board's poses held from the views step's "Next board pose", as `ctl` holds each through the
control channel; the browser test holds the first from the Simulator tab, which adds two tab
changes), the steps in the Commission tab, against the same steps through
`omnisort ctl` (`tests/ui/commissioning_flow.py`): 10 views of the held board, the intrinsics,
the camera and laser plane from the two-sided target, the robot registration, the verification
(map and locate). Each door on a fresh virtual cell (960 px) and a fresh `omnisort serve` on
the real drivers, no calibration at the start; the wall time of each step, and the
calibration against the virtual cell's truth.

The page's time includes what a person's clicks cannot skip (the live detection that shows
the target before it is calibrated, the pictures a step shows); a person adds their own
pace, which neither figure holds. It also includes the browser driver's own mechanics of each
click (the element found, shown, scrolled to the middle and at rest, then clicked: several
WebDriver round trips, about 0.15 s a click on 2 cores), which a person does not have:
`page_clicks_s` is their sum over the steps, and `page_less_clicks_over_ctl` the ratio without
them. `page_jobs_s` and `ctl_jobs_s`: the service's own time of each job, from its journal.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path
from typing import Any

WIDTH = 960


def _rounded(errors: dict[str, float]) -> dict[str, float]:
    return {k: round(v, 4) for k, v in errors.items()}


def _in_page(config: Path, port: int, tmp: Path) -> dict[str, float]:
    """The page's steps: `omnisort ui` for the service at `port`, Chromium signed in on it;
    each step's wall time, and (`clicks`) the time the driver spent in the steps' clicks."""
    from tests.ui import commissioning_flow as flow
    from tests.ui.browser_page import UI_S, open_cell_page, wait_for
    from tests.ui.ui_procs import quit_chromium, start_ui, stop_process

    ui_proc, url = start_ui(config, port, tmp)
    try:
        driver, page = open_cell_page(url)
        try:
            wait_for("the idle cell", lambda: page.text("state") == "idle", 30)
            clicked = [0.0]
            click = page.click

            def timed_click(name: str, timeout_s: float = UI_S) -> None:
                start = time.monotonic()
                click(name, timeout_s)
                clicked[0] += time.monotonic() - start

            page.click = timed_click  # type: ignore[method-assign]
            steps = flow.in_page(page, shots=False, first_from_simulator=False)
            return {**steps, "clicks": round(clicked[0], 1)}
        finally:
            quit_chromium(driver)
    finally:
        stop_process(ui_proc)


def run(shared: Path) -> dict[str, Any]:
    from omnisort_hw.service.launch import start_service
    from sim_backend.virtual_cell.launcher import VirtualCellProcess
    from tests.ui import commissioning_flow as flow

    out: dict[str, Any] = {"cell": f"virtual cell (scene sorting, {WIDTH} px), real drivers"}
    for door in ("page", "ctl"):
        with tempfile.TemporaryDirectory() as tmp_name:
            tmp = Path(tmp_name)
            with VirtualCellProcess("sorting", width=WIDTH, unlock_delay_s=5.0) as vc:
                config = flow.virtual_cell_file(vc, tmp)
                with start_service(config, tmp) as svc:
                    if door == "ctl":
                        out["ctl_s"] = flow.with_ctl(vc, svc.port)
                    else:
                        out["page_s"] = _in_page(config, svc.port, tmp)
                truth = vc.truth()
            # The service's own time of each job (its journal's `took_s`), as either door
            # started it: whatever the door's own overhead, the same work should take as long.
            took = json.loads((tmp / "state" / "job.json").read_text())["took_s"]
            out[f"{door}_jobs_s"] = {**took, "total": round(sum(took.values()), 1)}
            errors = flow.calibration_errors(tmp / "state" / "system.json", truth)
            out[f"{door}_calibration_error"] = _rounded(errors)
    out["page_clicks_s"] = out["page_s"].pop("clicks")
    out["page_over_ctl"] = round(out["page_s"]["total"] / out["ctl_s"]["total"], 2)
    net = out["page_s"]["total"] - out["page_clicks_s"]
    out["page_less_clicks_over_ctl"] = round(net / out["ctl_s"]["total"], 2)
    return out
