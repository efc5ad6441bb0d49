"""`omnisort ctl` prints a job's reply as one screen: its verdict first (a map that mapped
nothing says so and what to do), then its figures and files; `--json` keeps the whole reply.
The replies were 84 to 288 lines of JSON with the coverage warning buried inside."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.bad_files import good_calibration
from tests.service.conftest import Harness

pytestmark = pytest.mark.timeout(120)


def _ctl(port: int, *args: str) -> subprocess.CompletedProcess[str]:
    cmd = [sys.executable, "-m", "omnisort_hw.cli", "ctl", "--port", str(port), *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=60)


def test_a_map_that_mapped_nothing_says_so_on_one_screen(service: Harness, tmp_path: Path) -> None:
    camera, system = good_calibration()
    service.cell.store.save_camera(camera)
    service.cell.store.save_system(system)
    dark = tmp_path / "laser_off.png"
    assert cv2.imwrite(str(dark), np.full((640, 640, 3), 60, np.uint8))
    short = _ctl(service.running.port, "map", f"image={dark}", "picture=true")
    assert short.returncode == 0, short.stderr
    lines = short.stdout.splitlines()
    # No laser line in a laser-off image: nothing is measured, the check says why.
    assert lines[0] == "FAIL: laser map", lines
    assert "laser line: 0 px" in lines[1] and "no laser line in the image" in lines[1], lines
    assert "segments: 0 (>= 1)" in lines[2] and "is the laser on" in lines[2], lines
    assert any(line.startswith("overlay_png: ") for line in lines)
    assert len(lines) <= 20 and lines[-1] == "(the whole reply: --json)"
    whole = _ctl(service.running.port, "--json", "map", f"image={dark}")
    reply = json.loads(whole.stdout)
    assert reply["result"]["verdict"]["level"] == "fail"
    assert reply["result"]["segments"] == [] and not reply["result"]["laser_line"]["present"]
