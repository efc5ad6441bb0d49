"""The Simulator tab's checks on a commissioned virtual cell whose drift watchdog checks every
`period_s` (run by the commissioning's browser test after its sort):

- a knock from the page is caught by the watchdog within one period (by the first check that
  takes its frame after the knock): the page's drift banner, motion refused, the angle
  measured near the knock;
- the camera mounted at 5 deg of roll from the page: the renderer's own truth says 5 deg and
  the streamed frame is its picture;
- a cube, the target and the tool (to an XYZ of the base, after the confirmation) moved from
  the page land where asked.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from sim_backend.virtual_cell.launcher import VirtualCellProcess
from tests.sim.virtual_cell_fixture import streamed_frame
from tests.ui.browser_page import UI_S, Page, service_status, wait_for
from tests.ui.commissioning_flow import ctl, sim_note_after

KNOCK_DEG = 0.3
TOOL_B_MM = (-300.0, -350.0, 300.0)  # where the tool is sent, in the robot base's frame


def in_simulator_tab(
    vc: VirtualCellProcess, page: Page, port: int, period_s: float, tmp: Path
) -> dict[str, Any]:
    """The checks' measurements (asserted by `check`)."""
    ctl(port, "check")
    out: dict[str, Any] = {"period_s": period_s}
    page.click("tab-simulator")
    wait_for("the truth", lambda: page.text("sim-truth").startswith("camera:"), UI_S)

    # Every check that ends from here on, in order (each periodic check's `last` is new: they
    # are a period apart, so each `checked_at` differs), read while the watchdog runs.
    before = service_status(port)["drift"]["last"]
    checks: list[dict[str, Any]] = []

    def note_check() -> None:
        last = service_status(port)["drift"]["last"]
        if last is not None and last != before and (not checks or last != checks[-1]):
            checks.append(last)

    def banner() -> str | bool:
        note_check()
        return (t := page.text("drift")).startswith("Calibration drift") and t

    # A knock beyond what a knock is: refused in the page by the channel's schema, not sent.
    mounted = vc.truth()["camera_rotation"]
    page.type("sim-knock-angle_deg", "1000")
    out["refused_knock"] = sim_note_after(page, "sim-knock", "knock: not sent")
    # A joint that is not a number: refused by the same schema, before the confirmation.
    page.type("sim-joints-q_deg-2", "abc")
    out["refused_joints"] = sim_note_after(page, "sim-joints", "joints: not sent")
    out["mounted_unchanged"] = vc.truth()["camera_rotation"] == mounted
    page.type("sim-knock-angle_deg", f"{KNOCK_DEG}")
    sim_note_after(page, "sim-knock", "camera knocked")
    knocked_at = time.monotonic()
    out["alarm"] = wait_for("the drift banner", banner, 3 * period_s + 120.0, 0.1)
    note_check()
    out["checks"] = checks
    out["caught_s"] = time.monotonic() - knocked_at
    out["drift"] = service_status(port)["drift"]

    out["knocked"] = streamed_frame(vc.host)
    page.type("sim-camera-roll_deg", "5")
    sim_note_after(page, "sim-mount", "camera mounted at roll 5")
    wait_for("the truth shown", lambda: "roll 5.000" in page.text("sim-truth"), UI_S)
    out["streamed"] = streamed_frame(vc.host)
    vc.control("render", timeout_s=120.0, folder=str(tmp / "renders"), name="rolled")
    out["rendered"] = cv2.imread(str(tmp / "renders" / "rolled.png"))
    out["rendered_truth"] = json.loads((tmp / "renders" / "rolled.truth.json").read_text())

    page.type("sim-cube-index", "1")
    page.type("sim-cube-x_mm", "0")
    page.type("sim-cube-y_mm", "1000")
    page.type("sim-cube-yaw_deg", "10")
    sim_note_after(page, "sim-cube-move", "cube move: done")
    out["cubes"] = vc.truth()["cubes"]
    page.type("sim-target-x_mm", "40")
    page.type("sim-target-y_mm", "680")
    sim_note_after(page, "sim-target", "target two-sided set")
    out["target"] = vc.truth()["target"]
    for axis, value in zip("xyz", TOOL_B_MM, strict=True):
        page.type(f"sim-move_to-{axis}_mm", f"{value:g}")
    page.click("sim-move-to")
    page.confirm()
    wait_for("the move", lambda: page.text("sim-note").startswith("tool at the point"), 120, 0.2)
    out["tool"] = vc.truth()["tcp_B_mm"]
    page.shot("sim_panel", at="sim-note")
    return out


def check(out: dict[str, Any]) -> None:
    """The measurements against what the page asked."""
    refused = out["refused_knock"]
    assert "angle_deg" in refused and "maximum of 10" in refused, refused
    assert out["mounted_unchanged"], "a refused knock turned the camera"
    joints = out["refused_joints"]
    assert "q_deg.2: 'abc' is not of type 'number'" in joints, joints
    # Within one period: the first check that takes its frame after the knock finds it. At
    # most one check ends after the knock without finding it, the one under way when the
    # camera was knocked (its frame taken before), so at most two checks in all.
    checks = out["checks"]
    assert checks and checks[-1]["drift"], checks
    assert len(checks) <= 2, [(c["checked_at"], c["drift"]) for c in checks]
    # The angle measured is the knock's: the image check resolves a few hundredths of a
    # degree; 0.1 deg bounds it, as the recovery's test does.
    drift = out["drift"]
    assert drift["motion_refused"], drift
    angle = drift["last"]["angle_deg"]
    assert abs(angle - KNOCK_DEG) < 0.1, drift["last"]
    assert f"camera turned {angle:.3f} deg" in out["alarm"], out["alarm"]
    print(f"knock caught after {out['caught_s']:.1f} s, measured {angle:.3f} deg")

    # The renderer's own truth is at 5 deg, and the streamed frame is its picture: nearer to it
    # than the frame before by far (a periodic check may switch the laser off for a moment,
    # which changes the stripe's few pixels only).
    rotation = out["rendered_truth"]["camera_rotation"]
    assert abs(rotation["roll_deg"] - 5.0) < 1e-6, rotation
    rendered = out["rendered"].astype(float)
    near = np.abs(out["streamed"] - rendered).mean()
    far = np.abs(out["knocked"] - rendered).mean()
    assert near < far / 4, (near, far)

    assert np.allclose(out["cubes"][1]["center_S_mm"][:2], [0.0, 1000.0], atol=0.5)
    assert out["target"] == {"kind": "two-sided", "center_mm": [40.0, 680.0], "yaw_deg": 0.0}
    assert np.allclose(out["tool"], TOOL_B_MM, atol=1e-6), out["tool"]
