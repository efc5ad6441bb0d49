"""A job journal that survives a crash: SIGKILL `omnisort serve` mid-sort, start it again:
`status.last_run` reports the interrupted job, its progress and the cube in flight; the cell
refuses motion until `reset`; nothing resumes by itself; no file in the state directory is
half-written."""

from __future__ import annotations

import json
import signal
import time
from pathlib import Path

import pytest

from omnisort_hw.service.client import Client
from omnisort_hw.service.demo import calibrate_from_truth, write_config
from omnisort_hw.service.launch import start_service

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]


def _journal(state: Path) -> dict:
    try:
        return json.loads((state / "job.json").read_text())
    except (FileNotFoundError, ValueError):
        return {}


def test_sigkill_mid_sort_then_restart(tmp_path: Path) -> None:
    from tests.service.sim_cell import WIDTH

    config = write_config(tmp_path, WIDTH)
    calibrate_from_truth(config)
    state = tmp_path / "state"
    first = start_service(config, tmp_path / "run1")
    try:
        with Client(first.host, first.port, timeout_s=10) as c:
            c.send("sort")
            deadline = time.monotonic() + 120
            while True:
                rec = _journal(state)
                if rec.get("progress") and (rec.get("in_flight") or {}).get("phase") == "holding":
                    break
                assert time.monotonic() < deadline, f"no cube in flight after a sorted one: {rec}"
                time.sleep(0.005)
            first.proc.send_signal(signal.SIGKILL)
            first.proc.wait(10)
    finally:
        first.stop()
    killed_at = _journal(state)
    second = start_service(config, tmp_path / "run2")
    try:
        with Client(second.host, second.port, timeout_s=60) as c:
            st = c.call("status")["result"]
            joints0 = st["devices"]["arm"]["joints_deg"]
            refused = [c.call("move", {"joints_deg": joints0}), c.call("sort")]
            time.sleep(1.0)
            later = c.call("status")["result"]
            reset = c.call("reset")
            after = c.call("status")["result"]
    finally:
        assert second.stop() == 0
    last = st["last_run"]
    assert st["state"] == "fault" and "interrupted" in st["reason"]
    assert last["job"] == "sort" and last["state"] == "interrupted"
    assert last["pid"] == first.proc.pid
    assert len(last["progress"]) >= 1 and last["progress"] == killed_at["progress"]
    flight = last["in_flight"]
    assert flight["phase"] == "holding" and flight["color"] and flight["bin"] == flight["color"]
    assert flight == killed_at["in_flight"]
    assert st["gripper"]["lost"] == flight  # the restarted simulator's gripper is empty
    for r in refused:
        assert r["error"]["code"] == "motion_refused", r
    assert later["job"] is None and later["devices"]["arm"]["joints_deg"] == joints0
    assert reset["ok"] and after["state"] == "idle"
    assert not list(state.rglob("*.tmp")), list(state.rglob("*.tmp"))
    for p in state.rglob("*.json"):
        json.loads(p.read_text())
