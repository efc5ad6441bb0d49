"""The commissioning of docs/simulator.md, re-run as the doc gives it: every `omnisort` line of
its steps, in a fresh copy of `deploy/`, timed one by one. The command line calibrates
(views, intrinsics, extrinsics, registration), maps, locates and sorts; then the service on
the same cell file adopts the command line's files and sorts, with no second calibration.

The doc's `omnisort serve ... &` is started here on a free loopback port, and its `ctl` lines
are sent to that port; everything else runs as written.
"""

from __future__ import annotations

import json
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "simulator.md"


def doc_steps(doc: Path = DOC) -> list[str]:
    """The `omnisort` command lines of the doc's commissioning section, in order."""
    text = doc.read_text()
    start = text.index("## Commissioning")
    end = text.index("\n## ", start + 1)
    lines = [line.strip() for line in text[start:end].splitlines()]
    return [line for line in lines if re.match(r"^omnisort \w", line)]


def _run(words: list[str], cwd: Path) -> tuple[subprocess.CompletedProcess[str], float]:
    args = [w for word in words for w in (sorted(cwd.glob(word)) if "*" in word else [word])]
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "omnisort_hw.cli", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=900,
    )
    return proc, time.perf_counter() - t0


def run(shared: Path) -> dict[str, Any]:
    from omnisort_hw.service.launch import start_service

    steps = doc_steps()
    work = Path(tempfile.mkdtemp(prefix="omnisort-commissioning-"))
    shutil.copytree(ROOT / "deploy", work / "deploy")
    timings: dict[str, float] = {}
    service = None
    sorted_cli = sorted_service = None
    try:
        for step in steps:
            words = shlex.split(step.rstrip("&").strip())[1:]
            name = (
                " ".join(words[:2])
                if words[0] in ("sim", "intrinsics", "extrinsics", "ctl")
                else words[0]
            )
            if words[0] == "serve":
                t0 = time.perf_counter()
                service = start_service(work / words[words.index("--config") + 1], work / "serve")
                timings[name] = round(time.perf_counter() - t0, 2)
                continue
            if words[0] == "ctl":
                assert service is not None, "the doc sends ctl commands before serve"
                words = ["ctl", "--port", str(service.port), "--json", *words[1:]]
            proc, seconds = _run(words, work)
            if proc.returncode != 0:
                raise RuntimeError(f"{step}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
            timings[name] = round(seconds, 2)
            if words[0] == "sort":
                sorted_cli = int(re.search(r"(\d+) sorted", proc.stdout).group(1))  # type: ignore[union-attr]
            if words[:1] == ["ctl"] and words[-1] == "sort":
                sorted_service = json.loads(proc.stdout)["result"]["totals"]["sorted"]
    finally:
        if service is not None:
            service.stop()
        shutil.rmtree(work, ignore_errors=True)
    calibration = ("sim checkerboard-views", "intrinsics calibrate", "extrinsics calibrate")
    return {
        "steps": len(steps),
        "step_wall_s": timings,
        "cli_calibration_wall_s": round(sum(timings[k] for k in calibration), 1),
        "cli_wall_s": round(
            sum(v for k, v in timings.items() if not k.startswith(("ctl", "serve"))), 1
        ),
        "service_wall_s": round(
            sum(v for k, v in timings.items() if k.startswith(("ctl", "serve"))), 1
        ),
        "wall_s": round(sum(timings.values()), 1),
        "cubes_sorted_cli": sorted_cli,
        "cubes_sorted_service": sorted_service,
    }
