"""The Commission tab's first step on the virtual cell with no calibration (the package's
`intrinsics_from_views` fixture): six views of a board held in front of the camera, walked
through the field from the Simulator tab, each kept by the service with the full board in it;
the intrinsics calibrated from them pass their verdict (asserted in the step) and become the
cell's camera calibration."""

from __future__ import annotations

import json

import pytest

from tests.ui.browser_page import service_status
from tests.ui.commissioned.shared import VIEWS, CellPage

pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]


def test_the_views_from_the_page_calibrate_the_camera(intrinsics_from_views: CellPage) -> None:
    c = intrinsics_from_views
    kept = sorted((c.tmp / "state" / "views").glob("*.png"))
    assert len(kept) == VIEWS, kept
    camera = json.loads((c.tmp / "state" / "camera.json").read_text())
    # Every view kept is used, none rejected; the rendered corners fit to a fraction of a
    # pixel (0.011 px in one run: the renderer's corners are exact but for the pixel grid).
    assert [p.rsplit("/", 1)[-1] for p in camera["images_used"]] == [p.name for p in kept]
    assert camera["images_rejected"] == [] and camera["rms_px"] < 0.2, camera["rms_px"]
    status = service_status(c.svc.port)
    assert status["calibration"]["files"]["camera"]["health"] == "ok", status["calibration"]
