"""The live view: a separate process (rerun's own CLI, saving what it receives) gets the
camera image, the laser points and the state changes from the service's gRPC stream while
the service runs a job, and the service still writes its `.rrd` file."""

from __future__ import annotations

import random
import socket
import subprocess
import time
import warnings
from pathlib import Path

import pytest

from omnisort_hw.cli.review_cmd import save_live_command
from omnisort_hw.config.live_view import LiveViewConfig
from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.runlog import entity_paths
from omnisort_hw.service.client import Client
from omnisort_hw.service.live_view import start_live_view
from omnisort_hw.service.server import Service, start_in_thread

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

# `map` without an image measures with a capture: its laser-on camera frame, the map's points
# and the service's state changes.
WANTED = {"/capture/stripe/on", "/map/points_S", "/service/state"}


def _free_address() -> tuple[str, int]:
    host = f"127.{random.randint(1, 254)}.{random.randint(0, 254)}.{random.randint(1, 254)}"
    with socket.socket() as s:
        s.bind((host, 0))
        return host, s.getsockname()[1]


def _received(path: Path) -> set[str]:
    if not path.exists() or path.stat().st_size == 0:
        return set()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return set(entity_paths(path))
    except Exception:
        return set()  # the receiver is mid-write


def test_a_separate_process_receives_image_laser_points_and_state_during_a_job(
    tmp_path: Path,
) -> None:
    from tests.service.sim_cell import calibrated_sim_cell

    cell = calibrated_sim_cell(tmp_path / "cell")
    host, port = _free_address()
    live = start_live_view(LiveViewConfig(True, host, port, None, "64MiB"), cell.runlog)
    assert live is not None
    running = start_in_thread(Service(cell, ServiceConfig(port=0, job_timeout_s=120)))
    out = tmp_path / "received.rrd"
    receiver = subprocess.Popen(
        save_live_command(f"{host}:{port}", out),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        with Client(running.host, running.port, timeout_s=120) as c:
            reply = c.call("map")
            assert reply["ok"], reply
        # What the receiver has is on its disk while the service still runs.
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not _received(out) >= WANTED:
            time.sleep(0.5)
        got = _received(out)
        assert got >= WANTED, got
        rrd = cell.runlog_path
    finally:
        running.stop()
        live.close()
        try:
            receiver.wait(timeout=20)
        except subprocess.TimeoutExpired:
            receiver.terminate()
            receiver.wait(timeout=10)
    assert rrd is not None and set(entity_paths(rrd)) >= WANTED
