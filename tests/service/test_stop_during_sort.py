"""`stop` during a sort ends the arm's motion within 0.1 s of arm time on the simulated arm,
paced to the wall clock as a real arm is: the arm moves for at most one control period (one
physics step, 1/240 s) after the service's stop reaches it."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.service.client import Client
from omnisort_hw.service.server import Service, start_in_thread

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")

STOP_BOUND_S = 0.1  # the bound, in the arm's time


def test_stop_during_a_sort_ends_the_motion_within_one_control_period(tmp_path: Path) -> None:
    from tests.service.sim_cell import calibrated_sim_cell

    cell = calibrated_sim_cell(tmp_path)
    arm = cell.devices.arm
    arm.realtime = True  # the arm's time runs with the wall clock, as on a real cell
    world = arm.cell.world
    period = world.time_step
    samples: list[float] = []  # arm time of every motion sample the arm carried out
    stops: list[float] = []  # arm time when arm.stop() was called
    moving = threading.Event()
    set_joints, stop = world.set_joints, arm.stop

    def record_sample(q: object) -> None:
        samples.append(world.sim_time)
        moving.set()
        set_joints(q)

    def record_stop() -> None:
        stops.append(world.sim_time)
        stop()

    world.set_joints = record_sample  # type: ignore[method-assign]
    arm.stop = record_stop  # type: ignore[method-assign]
    running = start_in_thread(Service(cell, ServiceConfig(port=0, job_timeout_s=120)))
    try:
        with (
            Client(running.host, running.port, timeout_s=120) as c,
            Client(running.host, running.port, timeout_s=10) as safety,
        ):
            rid = c.send("sort")
            assert moving.wait(90), "the arm never moved"
            time.sleep(0.3)  # well inside a move
            requested = world.sim_time
            before = samples[-1]
            assert safety.call("stop")["ok"]
            reply = c.read_reply()
            time.sleep(0.2)
    finally:
        running.stop()
    assert reply["id"] == rid and reply["error"]["code"] == "stopped", reply
    assert stops, "the service never stopped the arm"
    assert requested - before <= 10 * period  # it was moving when the stop was sent
    last = samples[-1]
    # At most the step in progress when stop() arrived: one control period.
    assert last - stops[0] <= period + 1e-9, (last, stops[0], period)
    # From the request to the end of motion, in arm time.
    print(f"\nstop: motion ended {1e3 * (last - requested):.1f} ms of arm time after the request")
    assert last - requested <= STOP_BOUND_S, (
        f"motion ended {1e3 * (last - requested):.1f} ms of arm time after the stop request"
    )
