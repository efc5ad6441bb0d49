"""`omnisort evaluate lighting`: one JSON object with single frame and capture per scenario."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.timeout(600)


def test_lighting_json_has_the_keys_and_the_capture_maps_no_spurious_point() -> None:
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "omnisort_hw.cli",
            "evaluate",
            "lighting",
            "--seed",
            "3",
            "--frames",
            "2",
            "--width",
            "640",
            "--scenario",
            "red_objects",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=580,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout)
    sc = out["scenarios"]["red_objects"]
    for key in ("single", "capture"):
        for field in ("spurious_points", "laser_points", "mapping_max_rel_error"):
            assert field in sc[key]
    assert sc["capture"]["laser_points"] > 30
    assert sc["capture"]["spurious_points"] == 0  # red tape and cubes vanish in the difference


def test_unknown_scenario_is_refused_by_name() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "omnisort_hw.cli", "evaluate", "lighting", "--scenario", "fog"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode != 0
    assert "fog" in proc.stderr


def test_table3_frames_needs_the_degraded_camera() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "omnisort_hw.cli", "evaluate", "table3", "--frames", "4"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode != 0
    assert "--degraded" in proc.stderr
