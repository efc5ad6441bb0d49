"""Kill a sweep half way, run it again: the finished trials are not run again and the rows
end up as an uninterrupted run's. The sweep is the real CLI in a subprocess, killed with
SIGKILL once two of its four rows are on disk; every wait has a timeout."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from tests.sweeps.conftest import FRAMES, SCENARIOS, SEED, WIDTH

pytestmark = pytest.mark.timeout(300)


def _command(folder: Path) -> list[str]:
    cmd = [sys.executable, "-m", "omnisort_hw.cli", "evaluate", "lighting"]
    cmd += ["--seed", str(SEED), "--frames", str(FRAMES), "--width", str(WIDTH)]
    for name in SCENARIOS:
        cmd += ["--scenario", name]
    return [*cmd, "--no-calibration", "--executor", "serial", "--sweep-dir", str(folder), "--json"]


def _lines(path: Path) -> list[bytes]:
    return path.read_bytes().splitlines(keepends=True) if path.is_file() else []


def test_a_killed_sweep_resumes_without_running_finished_trials(
    tmp_path: Path, serial_rows: list[dict[str, Any]]
) -> None:
    folder = tmp_path / "sweep"
    rows_path = folder / "rows.jsonl"
    proc = subprocess.Popen(_command(folder), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 180.0
        while len([ln for ln in _lines(rows_path) if ln.endswith(b"\n")]) < 2:
            assert proc.poll() is None, "the sweep ended before it could be killed"
            assert time.monotonic() < deadline, "no two rows within 180 s"
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=30)
    before = [ln for ln in _lines(rows_path) if ln.endswith(b"\n")]
    assert 2 <= len(before) < len(SCENARIOS), "killed too late to show a resume"
    # A kill can land inside a write; leave such a torn line for the resume to cut.
    with rows_path.open("ab") as f:
        f.write(before[-1][: len(before[-1]) // 2])

    done = subprocess.run(_command(folder), capture_output=True, text=True, timeout=240, check=True)
    assert f"{len(before)} trials were already done" in done.stderr
    after = _lines(rows_path)
    assert len(after) == len(SCENARIOS) and all(ln.endswith(b"\n") for ln in after)
    assert after[: len(before)] == before  # the finished rows were kept, not run again
    rows = [json.loads(ln) for ln in after]
    killed_pid = rows[0]["provenance"]["pid"]
    assert sum(r["provenance"]["pid"] == killed_pid for r in rows) == len(before)
    # The final rows are an uninterrupted run's (results; timing differs by design).
    by_key = {r["key"]: r["result"] for r in rows}
    assert [by_key[r["key"]] for r in serial_rows] == [r["result"] for r in serial_rows]
    # And the command's summary is built from all of them.
    summary = json.loads(done.stdout)["result"]
    assert list(summary["scenarios"]) == list(SCENARIOS)
