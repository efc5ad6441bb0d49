"""`view`, the live picture, and the pixels a `locate` reply gives for overlays, on the
simulated cell served in a thread: the picture is the camera's frame scaled to the width asked
(its content the same as a full capture's, scaled), it needs no token where `capture` does,
and a located cube's centre pixel lies on a patch of its own colour in the frame."""

from __future__ import annotations

import base64
from pathlib import Path

import cv2
import numpy as np
import pytest

from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.pipeline.replies import PictureFileReply, ViewReply
from omnisort_hw.service.client import Client
from omnisort_hw.service.server import Service, start_in_thread
from omnisort_hw.wire_records import from_wire, to_wire

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

WIDTH = 320
TOKEN = "view-test-token-1234"
# Dominant channels (BGR) of the scene's cube colours.
HUES = {"red": (2,), "green": (1,), "blue": (0,), "yellow": (1, 2)}


def _decode(reply: dict) -> np.ndarray:
    data = np.frombuffer(base64.b64decode(reply["base64"]), np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_COLOR)
    assert image is not None, "not a picture"
    return image


def test_view_is_the_frame_scaled_and_cubes_carry_their_pixels(tmp_path: Path) -> None:
    from tests.service.sim_cell import calibrated_sim_cell

    cell = calibrated_sim_cell(tmp_path, width=WIDTH)
    running = start_in_thread(Service(cell, ServiceConfig(port=0, token=TOKEN)))
    try:
        with Client(running.host, running.port, timeout_s=120) as anyone:
            assert anyone.call("capture")["error"]["code"] == "unauthorized"
            small = anyone.execute("view", {"width": 100, "quality": 90})
            assert (small["width"], small["height"], small["format"]) == (100, 100, "jpg")
            assert small["scale"] == pytest.approx(100 / WIDTH)
            full = anyone.execute("view", {"width": 4096})
            assert (full["width"], full["scale"]) == (WIDTH, 1.0)  # never enlarged
            assert to_wire(from_wire(ViewReply, full)) == full  # the record holds it all
            assert full["sequence"] > small["sequence"]  # a fresh frame each time
            # The small picture is the frame scaled: the same scene within JPEG's noise.
            frame, picture = _decode(full), _decode(small)
            scaled = cv2.resize(frame, (100, 100), interpolation=cv2.INTER_AREA)
            assert float(np.mean(np.abs(scaled.astype(float) - picture))) < 6.0
            bad = anyone.call("view", {"width": 10})
            assert bad["error"]["code"] == "bad_argument" and bad["error"]["field"] == "width"

        with Client(running.host, running.port, token=TOKEN, timeout_s=120) as operator:
            located = operator.execute("locate")
            image = _decode(operator.execute("view", {"width": WIDTH}))
            # The picture the location wrote, sent to a client; nothing else of the PC is.
            overlay = located["overlay_png"]
            sent = operator.execute("picture", {"path": overlay, "width": 200})
            assert to_wire(from_wire(PictureFileReply, sent)) == sent
            written = cv2.imread(overlay, cv2.IMREAD_COLOR)
            assert sent["width"] == 200 and sent["scale"] == pytest.approx(200 / written.shape[1])
            assert _decode(sent).shape[:2] == (sent["height"], 200)
            with Client(running.host, running.port) as anyone:
                denied = anyone.call("picture", {"path": overlay})
            assert denied["error"]["code"] == "unauthorized"
            state = Path(overlay).parent
            for path in (
                "/etc/passwd",
                str(state / "camera.json"),
                str(state / "none.png"),
                str(state / ".." / Path(overlay).name),
            ):
                refused = operator.call("picture", {"path": path})
                assert refused["error"]["code"] == "bad_input", (path, refused)
            relative = operator.call("picture", {"path": "locate_overlay.png"})
            assert relative["error"]["code"] == "bad_argument"
        assert located["cubes"], located
        for cube in located["cubes"]:
            u, v = cube["center_px"]
            ring = np.asarray(cube["ellipse_px"], float)
            assert ring.shape == (25, 2) and cube["ellipse_scale"] == 10.0
            # The ellipse is centred on the cube (its first and last points are the same).
            assert np.allclose(ring[:-1].mean(axis=0), (u, v), atol=0.5)
            patch = image[round(v) - 1 : round(v) + 2, round(u) - 1 : round(u) + 2]
            bgr = patch.reshape(-1, 3).mean(axis=0)
            strong = HUES[cube["color"]]
            weak = [c for c in range(3) if c not in strong]
            assert min(bgr[list(strong)]) > max(bgr[weak]) + 40, (cube["color"], bgr)
    finally:
        running.stop()
