"""The wall separation against the image's own scale: the floor board in the calibration
image says how far the walls are apart, whatever separation was typed. `--separation 900` on
walls 1084.5 mm apart gave a 664 mm laser distance and no warning."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("pybullet", reason="the target is rendered by the simulated cell")
pytestmark = pytest.mark.timeout(600)

TRUE_SEPARATION_MM = 1084.5  # the sorting scene's inner wall distance


def _calibrate(tmp: Path, separation: float) -> dict:
    from omnisort_hw.service.demo import calibrate_from_truth, write_config

    work = tmp / f"sep{separation:g}"
    work.mkdir()
    config = write_config(work, 960)  # the commissioning size: 640 px loses a marker
    calibrate_from_truth(config)  # only camera.json is used: the truth's intrinsics
    cmd = [sys.executable, "-m", "omnisort_hw.cli", "extrinsics", "calibrate"]
    cmd += ["--config", str(config), "--camera", str(work / "state" / "camera.json")]
    cmd += ["--target", "two-sided", "--separation", f"{separation:g}"]
    cmd += ["--out", str(work / "system.json"), "--json"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return dict(json.loads(proc.stdout)["result"])


@pytest.mark.parametrize(("separation", "level"), [(TRUE_SEPARATION_MM, "pass"), (900.0, "fail")])
def test_the_floor_board_gives_the_separation_whatever_was_typed(
    tmp_path: Path, separation: float, level: str
) -> None:
    result = _calibrate(tmp_path, separation)
    scale = result["scale_check"]
    # The implied separation is the true one either way (the simulator's noise: 0.01 %).
    assert scale["implied_separation_mm"] == pytest.approx(TRUE_SEPARATION_MM, rel=0.002), scale
    checks = {c["name"]: c for c in result["verdict"]["checks"]}
    check = checks["separation against the floor board's scale"]
    assert check["level"] == level, check
    assert result["verdict"]["level"] == level
    if level == "fail":
        assert "1084" in check["advice"] and "900.0 mm was given" in check["advice"]
