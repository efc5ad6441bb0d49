"""The gripper's load is state: a cube held when an estop cuts a pick short is reported in
`status`, and the next `sort` first places it in its bin; every cube the reports call sorted
is in the bin of its colour by the simulator's truth."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.service.client import Client
from omnisort_hw.service.server import Service, start_in_thread

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]


def test_held_cube_reported_after_estop_and_placed_by_the_next_sort(tmp_path: Path) -> None:
    from sim_backend.sort_harness import SimVerifier
    from tests.service.sim_cell import calibrated_sim_cell

    cell = calibrated_sim_cell(tmp_path)
    arm = cell.devices.arm
    grip = arm.gripper
    verifier = SimVerifier(arm)
    n_cubes = len(verifier.true_cubes())
    grasped, estopped = threading.Event(), threading.Event()
    close = grip.close

    def close_then_wait(timeout_s: float = 3.0) -> None:
        close(timeout_s)
        if grip.holding and not grasped.is_set():
            grasped.set()
            estopped.wait(30)  # the estop arrives while the cube is in the gripper

    grip.close = close_then_wait  # type: ignore[method-assign]
    running = start_in_thread(Service(cell, ServiceConfig(port=0, job_timeout_s=240)))
    try:
        with (
            Client(running.host, running.port, timeout_s=240) as c,
            Client(running.host, running.port) as safety,
        ):
            rid = c.send("sort")
            assert grasped.wait(120), "no cube was grasped"
            held_body = grip.held_body
            assert safety.call("estop")["ok"]
            estopped.set()
            first = c.read_reply()
            assert first["id"] == rid and first["error"]["code"] == "stopped", first
            cell.refresh_status()
            st = safety.call("status")["result"]
            held_truth = next(t for t in verifier.true_cubes() if t.body == held_body)
            assert c.call("reset")["ok"]
            second = c.call("sort")
    finally:
        running.stop()
    load = st["gripper"]
    assert st["state"] == "fault"
    assert load["load"] == "held" and load["sensor"] is True
    assert load["cube"]["color"] == held_truth.color and load["cube"]["phase"] == "holding"
    assert st["last_run"]["state"] == "stopped"
    assert st["last_run"]["in_flight"]["color"] == held_truth.color
    assert second["ok"], second
    report = second["result"]
    placed = report["cubes"][0]
    assert placed["status"] == "sorted" and placed["color"] == held_truth.color
    assert "held from" in placed["reason"]
    final = {t.body: t for t in verifier.true_cubes()}
    assert verifier.bin_of(final[held_body].center_S) == held_truth.color
    in_right_bin = sum(verifier.bin_of(t.center_S) == t.color for t in final.values())
    # The stop came at the first grasp: the second sort placed the held cube, then the rest.
    assert report["totals"]["sorted"] == in_right_bin == n_cubes, (
        report["totals"],
        {t.color: verifier.bin_of(t.center_S) for t in final.values()},
    )
