"""`detect`, the live detection a screen shows while a target is placed, on the simulated cell
served in a thread: what it finds lies where the simulator drew it (markers, the stripe, the
floor board's corners), a target it cannot find says why and shows the blue markers it saw,
and bad input is refused with the field named."""

from __future__ import annotations

import base64
from pathlib import Path

import cv2
import numpy as np
import pytest

from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.pipeline.replies import DetectReply
from omnisort_hw.service.client import Client
from omnisort_hw.service.server import Service, start_in_thread
from omnisort_hw.wire_records import from_wire, to_wire

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

WIDTH = 960  # the size the operator interface's tests use; the markers are too small at 320
TOKEN = "detect-test-token-5678"
# A blob's centroid against the projected centre of its square: the projection bends the
# square, which moves its centroid by a small fraction of its size (here 10 to 24 px across),
# plus a quarter pixel of the centroid's own noise.
MARKER_TOL = 0.1  # of the marker's extent in the image
MARKER_NOISE_PX = 0.25
# A saddle corner at sub-pixel accuracy on a sharp render.
CORNER_TOL_PX = 0.5
# The stripe's ridge against the true line: half its rendered width (a few px) at most.
STRIPE_TOL_PX = 2.0


def _layers(reply: dict, kind: str) -> np.ndarray:
    parts = [np.asarray(x["pixels"], float).reshape(-1, 2) for x in reply["layers"]]
    kinds = [x["kind"] for x in reply["layers"]]
    chosen = [p for p, k in zip(parts, kinds, strict=True) if k == kind]
    return np.vstack(chosen) if chosen else np.empty((0, 2))


def _nearest(points: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Each point's distance to the nearest truth point."""
    return np.min(np.linalg.norm(points[:, None, :] - truth[None, :, :], axis=2), axis=1)


def test_detection_lies_where_the_simulator_drew_it(tmp_path: Path) -> None:
    from tests.service.sim_cell import calibrated_sim_cell

    cell = calibrated_sim_cell(tmp_path, width=WIDTH)
    cam = cell.devices.camera
    cell.set_laser(True)
    on = cam.grab(with_truth=True)
    truth = cam.last_truth
    cv2.imwrite(str(tmp_path / "on.png"), on.image)
    cell.set_laser(False)
    cv2.imwrite(str(tmp_path / "off.png"), cam.grab().image)
    cv2.imwrite(str(tmp_path / "small.png"), cv2.resize(on.image, (WIDTH // 2, WIDTH // 2)))
    running = start_in_thread(Service(cell, ServiceConfig(port=0, token=TOKEN)))
    try:
        with Client(running.host, running.port, timeout_s=120) as anyone:
            assert anyone.call("detect")["error"]["code"] == "unauthorized"
        with Client(running.host, running.port, token=TOKEN, timeout_s=120) as op:
            target = op.execute("detect", {"image": str(tmp_path / "on.png"), "width": 480})
            floor = op.execute("detect", {"what": "floor", "image": str(tmp_path / "off.png")})
            dark = op.execute("detect", {"image": str(tmp_path / "off.png")})
            # Live: the laser as it is (off here), a picture of the same frame.
            live = op.execute("detect", {"what": "floor", "width": 200})
            bad_board = op.call("detect", {"what": "board", "board": "7"})
            wrong_size = op.call("detect", {"image": str(tmp_path / "small.png")})
            board_for_floor = op.call("detect", {"what": "floor", "board": "9x6"})
    finally:
        running.stop()
    for reply in (target, floor, dark, live):  # the record holds it all, the picture too
        assert to_wire(from_wire(DetectReply, reply)) == reply

    assert target["found"] and "problem" not in target, target["summary"]
    assert (target["image_width"], target["image_height"]) == (WIDTH, WIDTH)
    assert {x["name"] for x in target["layers"]} >= {
        f"{w} wall {k}" for w in ("left", "right") for k in ("border", "laser", "markers")
    }
    markers = _layers(target, "marker")
    seen = [m for m in truth["markers_px"] if m["visible"]]
    true_markers = np.array([m["center_px"] for m in seen], float)
    extent = np.array([np.ptp(np.asarray(m["corners_px"], float), axis=0).max() for m in seen])
    assert len(markers) == 8
    gap = markers[:, None, :] - true_markers[None, :, :]
    nearest = np.argmin(np.linalg.norm(gap, axis=2), axis=1)
    assert sorted(nearest) == list(range(8))  # each marker found once
    off = np.linalg.norm(markers - true_markers[nearest], axis=1)
    assert np.all(off < MARKER_TOL * extent[nearest] + MARKER_NOISE_PX), (off, extent)
    true_stripe = np.vstack(
        [np.asarray(p["points_px"], float) for p in truth["laser_polylines_px"]]
    )
    assert _nearest(_layers(target, "laser"), true_stripe).max() < STRIPE_TOL_PX
    picture = target["picture"]
    assert (picture["width"], picture["scale"]) == (480, 0.5)
    image = cv2.imdecode(np.frombuffer(base64.b64decode(picture["base64"]), np.uint8), 1)
    assert image.shape[:2] == (480, 480)

    floor_board = next(b for b in truth["checkerboards"] if b["on_floor"])
    corners = _layers(floor, "corner")
    assert floor["found"] and len(corners) == 54, floor["summary"]
    assert _nearest(corners, np.asarray(floor_board["corners_px"], float)).max() < CORNER_TOL_PX

    # No stripe without the laser: not found, why, and the eight markers the operator can see.
    assert not dark["found"] and "laser" in dark["problem"], dark
    assert len(_layers(dark, "marker")) >= 8 and dark["summary"].startswith("the two-sided")
    assert live["found"] and live["picture"]["width"] == 200, live["summary"]

    assert bad_board["error"]["code"] == "bad_input" and "board" in bad_board["error"]["message"]
    assert wrong_size["error"]["code"] == "bad_input", wrong_size
    assert board_for_floor["error"]["code"] == "bad_argument"
    assert board_for_floor["error"]["field"] == "board"
