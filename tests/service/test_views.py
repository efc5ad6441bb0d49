"""`views`, the intrinsics' views taken from the live camera, on the simulated cell served in a
thread: a frame with the full board is kept (its image and the board's outline, which is the
true board's), one without it is refused with the detector's reason and nothing written; the
coverage of the image circle's rim and the verdict follow the views; remove and clear take
them out; a second board size is refused while views of the first are kept."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.core.intrinsics import MIN_IMAGES
from omnisort_hw.pipeline.replies import ViewsReply
from omnisort_hw.service.client import Client
from omnisort_hw.service.server import Service, start_in_thread
from omnisort_hw.wire_records import from_wire, to_wire

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

WIDTH = 960  # the floor board's squares are 8 px across here: a sharp detection
TOKEN = "views-test-token-9012"
CORNER_TOL_PX = 0.5  # a saddle corner at sub-pixel accuracy on a sharp render


def test_views_are_kept_covered_removed_and_cleared(tmp_path: Path) -> None:
    from tests.service.sim_cell import calibrated_sim_cell

    cell = calibrated_sim_cell(tmp_path, width=WIDTH)
    cam = cell.devices.camera
    cam.grab(with_truth=True)
    floor = next(b for b in cam.last_truth["checkerboards"] if b["on_floor"])
    cols, rows = floor["inner_corners"]
    running = start_in_thread(Service(cell, ServiceConfig(port=0, token=TOKEN)))
    try:
        with Client(running.host, running.port, token=TOKEN, timeout_s=120) as op:
            empty = op.execute("views")
            absent = op.call("views", {"action": "add", "board": "7x4"})
            nothing = sorted(Path(empty["folder"]).glob("*"))
            first = op.execute("views", {"action": "add", "board": f"{cols}x{rows}"})
            image = cv2.imread(str(Path(first["folder"]) / "view_001.png"))
            second = op.execute("views", {"action": "add", "board": f"{cols}x{rows}"})
            other = op.call("views", {"action": "add", "board": "7x4"})
            removed = op.execute("views", {"action": "remove", "name": "view_001"})
            missing = op.call("views", {"action": "remove", "name": "view_001"})
            no_name = op.call("views", {"action": "remove"})
            third = op.execute("views", {"action": "add", "board": f"{cols}x{rows}"})
            cleared = op.execute("views", {"action": "clear"})
        with Client(running.host, running.port, timeout_s=30) as anyone:
            denied = anyone.call("views")
    finally:
        running.stop()
    for reply in (empty, first, second, removed, third, cleared):  # the record holds it all
        assert to_wire(from_wire(ViewsReply, reply)) == reply

    folder = Path(first["folder"])
    assert folder == tmp_path / "state" / "views"
    assert empty["count"] == 0 and "coverage" not in empty
    assert empty["verdict"]["level"] == "fail" and empty["need"] == MIN_IMAGES

    assert first["added"] == "view_001" and second["added"] == "view_002"
    assert second["count"] == 2 and [v["name"] for v in second["views"]] == ["view_001", "view_002"]
    assert (second["image_width"], second["board"]) == (WIDTH, f"{cols}x{rows}")
    # The kept image is the frame, and the outline is the true board's outer corners, in order.
    assert image is not None and image.shape[:2] == (WIDTH, WIDTH)
    outline = np.asarray(first["views"][0]["outline_px"], float)
    grid = np.asarray(floor["corners_px"], float).reshape(rows, cols, 2)
    true_ring = np.concatenate([grid[0, :], grid[1:, -1], grid[-1, -2::-1], grid[-2:0:-1, 0]])
    assert outline.shape == (2 * (cols + rows) - 4, 2)
    dist = np.linalg.norm(outline[:, None, :] - true_ring[None, :, :], axis=2)
    nearest = np.argmin(dist, axis=1)
    assert sorted(nearest) == list(range(len(true_ring)))  # each outer corner once
    assert dist.min(axis=1).max() < CORNER_TOL_PX
    # ...in order around the board: each step to a neighbour on the true ring.
    steps = (np.diff(np.append(nearest, nearest[0])) % len(true_ring)).tolist()
    assert set(steps) in ({1}, {len(true_ring) - 1}), steps

    # The floor board lies well inside the image circle: the rim is not covered, and the verdict
    # says so (and fails for too few views).
    cov = second["coverage"]
    radius = cov["radius_px"]
    centre = np.asarray(cov["centre_px"])
    assert 0.4 * WIDTH < radius <= 0.5 * WIDTH + 1
    far = float(np.max(np.linalg.norm(grid.reshape(-1, 2) - centre, axis=1)))
    inner = (1.0 - cov["outer_band"]) * radius
    assert far < inner and cov["fraction"] == 0.0 and not any(cov["covered"]), (far, inner)
    assert sum(cov["inside"]) == len(cov["inside"])  # the circle is inside the square frame
    levels = {c["name"]: c["level"] for c in second["verdict"]["checks"]}
    assert levels == {
        "views with the full board": "fail",
        "outer band of the image circle covered": "warn",
    }

    assert absent["error"]["code"] == "feature_not_found", absent
    assert "7x4" in absent["error"]["message"] and nothing == []  # nothing written
    assert other["error"]["code"] == "bad_input" and "9x6" in other["error"]["message"]
    assert removed["removed"] == ["view_001"] and removed["count"] == 1
    assert missing["error"]["code"] == "bad_input" and "view_001" in missing["error"]["message"]
    assert no_name["error"]["code"] == "bad_argument" and no_name["error"]["field"] == "name"
    assert third["added"] == "view_003"  # names are never reused
    assert cleared["count"] == 0 and sorted(cleared["removed"]) == ["view_002", "view_003"]
    assert not list(folder.iterdir())
    assert denied["error"]["code"] == "unauthorized"
