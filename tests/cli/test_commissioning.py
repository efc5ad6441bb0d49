"""The commissioning steps of docs/simulator.md, run as written on `deploy/cell.sim.toml`:
render the checkerboard views, intrinsics, extrinsics, register-robot, map, locate, sort (the
last four capture with the simulated camera and laser, no image files); then the service on
the same cell file adopts the command line's calibration and sorts, with no second
calibration."""

from __future__ import annotations

import json
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("pybullet")

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "simulator.md"

# The steps exactly as docs/simulator.md gives them (the test checks the doc still does).
STEPS = (
    "omnisort sim checkerboard-views --n 10 --seed 1 --width 960 --out build/sim-cell/views",
    "omnisort intrinsics calibrate build/sim-cell/views/*.png --square 116 "
    "--out build/sim-cell/camera.json",
    "omnisort extrinsics calibrate --config deploy/cell.sim.toml "
    "--camera build/sim-cell/camera.json --target two-sided --separation 1084.5 "
    "--out build/sim-cell/system.json",
    "omnisort register-robot --config deploy/cell.sim.toml --system build/sim-cell/system.json",
    "omnisort map --config deploy/cell.sim.toml --system build/sim-cell/system.json",
    "omnisort locate --config deploy/cell.sim.toml --system build/sim-cell/system.json",
    "omnisort sort --config deploy/cell.sim.toml --system build/sim-cell/system.json",
)
# Then the service (started by the test on a free port, `omnisort serve --config
# deploy/cell.sim.toml` in the doc) takes the same files and sorts.
SERVICE_STEPS = (
    "omnisort ctl adopt camera=build/sim-cell/camera.json system=build/sim-cell/system.json",
    "omnisort ctl sort",
)


def _run(step: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """One documented command, `omnisort` being this interpreter's CLI, the glob expanded."""
    words = shlex.split(step)[1:]
    args = [w for word in words for w in (sorted(cwd.glob(word)) if "*" in word else [word])]
    return subprocess.run(
        [sys.executable, "-m", "omnisort_hw.cli", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_the_doc_gives_these_steps() -> None:
    text = " ".join(DOC.read_text().split())
    for step in (*STEPS, *SERVICE_STEPS):
        assert step in text, step


@pytest.mark.slow
@pytest.mark.timeout(1800)  # seven commands, each with its own 600 s bound
def test_commissioning_steps_run_on_the_shipped_sim_cell(tmp_path: Path) -> None:
    shutil.copytree(ROOT / "deploy", tmp_path / "deploy")
    outputs = []
    for step in STEPS:
        proc = _run(step, tmp_path)
        assert proc.returncode == 0, f"{step}\n{proc.stderr[-3000:]}"
        outputs.append(proc.stdout)
    # Each measuring step of the doc's recipe passes its own verdict (docs/verdicts.md).
    for i, what in ((1, "intrinsics"), (2, "extrinsics"), (3, "robot registration")):
        assert f"PASS: {what}" in outputs[i], outputs[i]
    assert "PASS: laser map" in outputs[4] and "PASS: locate" in outputs[5]
    assert "PASS: sort" in outputs[6], outputs[6]
    system = json.loads((tmp_path / "build" / "sim-cell" / "system.json").read_text())
    assert system["robot_base"]["image"] == "capture"
    assert "4 cubes" in outputs[5]
    assert "4 sorted, 0 skipped, 0 failed" in outputs[6]
    assert "4 in the right bin, 0 collisions" in outputs[6]
    # The sort is in the cell's job journal as the service would have it, nothing in flight.
    job = json.loads((tmp_path / "build" / "sim-cell" / "state" / "job.json").read_text())
    assert (job["job"], job["state"], job["in_flight"]) == ("sort", "done", None), job
    _service_steps(tmp_path)


def _service_steps(tmp_path: Path) -> None:
    """The service on the commissioned cell file: the CLI's files adopted, then a sort of the
    (new) world's four cubes, every one in its bin."""
    from omnisort_hw.service.launch import start_service

    with start_service(tmp_path / "deploy" / "cell.sim.toml", tmp_path / "serve") as service:
        replies = []
        for step in SERVICE_STEPS:
            ctl, rest = step.split(" ctl ")
            proc = _run(f"{ctl} ctl --port {service.port} --json {rest}", tmp_path)
            assert proc.returncode == 0, f"{step}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
            replies.append(json.loads(proc.stdout)["result"])
    assert set(replies[0]["adopted"]) == {"camera", "system"}
    assert replies[0]["drift_reference"] is True
    totals = replies[1]["totals"]
    assert (totals["cubes"], totals["sorted"], totals["failed"]) == (4, 4, 0), totals


def test_register_robot_without_registration_settings_is_an_input_error(tmp_path: Path) -> None:
    proc = _run("omnisort register-robot image.png --system system.json --square 40", tmp_path)
    assert proc.returncode == 2
    assert "--offset is needed" in proc.stderr
