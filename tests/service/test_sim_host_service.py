"""The service on the simulated cell hosted in a child process (what `omnisort serve` opens):
capture and move through the proxies, `stop` ends a move within one control period of arm
time, a child killed mid-job makes the job's reply a typed error while the service keeps
answering, and closing the service leaves no child process."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.service.client import Client
from omnisort_hw.service.server import Service, start_in_thread
from tests.service.procs import process_gone

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

STOP_BOUND_S = 0.1  # the bound, in the arm's time


def _wait_moving(arm: object, samples: int, within_s: float = 90.0) -> None:
    deadline = time.monotonic() + within_s
    while arm.motion_trace()["samples"] < samples:  # type: ignore[attr-defined]
        assert time.monotonic() < deadline, "the arm never moved"
        time.sleep(0.01)


def test_capture_move_and_stop_through_the_hosted_devices(tmp_path: Path) -> None:
    from tests.service.sim_cell import calibrated_sim_cell

    cell = calibrated_sim_cell(tmp_path, devices_in_child=True)
    arm = cell.devices.arm
    pid = arm.host_pid  # type: ignore[union-attr]
    assert pid != os.getpid()
    running = start_in_thread(Service(cell, ServiceConfig(port=0, job_timeout_s=120)))
    try:
        with (
            Client(running.host, running.port, timeout_s=120) as c,
            Client(running.host, running.port, timeout_s=10) as safety,
        ):
            shot = c.call("capture", {"encoding": "base64"})
            assert shot["ok"], shot
            assert (shot["result"]["width"], shot["result"]["height"]) == (320, 320)
            home = np.asarray(arm.cell.scene.robot.home_deg, float)
            target = home + np.array([15.0, 0, 0, 0, 0, 0])
            moved = c.call("move", {"joints_deg": target.tolist()})
            assert moved["ok"], moved
            np.testing.assert_allclose(arm.joint_positions(), target, atol=1e-6)
            # A long move paced to the wall clock, stopped from another connection.
            arm.realtime = True
            period = arm.cell.read("world.time_step")
            arm.motion_trace()
            rid = c.send("move", {"joints_deg": (home - np.array([60.0, 0, 0, 0, 0, 0])).tolist()})
            _wait_moving(arm, 40)
            requested = arm.motion_trace()["now"]
            assert safety.call("stop")["ok"]
            reply = c.read_reply()
            trace = arm.motion_trace()
            st = safety.call("status")
            assert st["ok"] and st["result"]["devices"]["arm"]["connected"] is True
    finally:
        running.stop()
    assert reply["id"] == rid and reply["error"]["code"] == "stopped", reply
    assert trace["stops"], "the service's stop never reached the arm"
    assert trace["last_sample"] - trace["stops"][0] <= period + 1e-9, trace
    print(f"\nstop: motion ended {1e3 * (trace['last_sample'] - requested):.1f} ms of arm time")
    assert trace["last_sample"] - requested <= STOP_BOUND_S, (trace, requested)
    assert process_gone(pid), "the service's shutdown left the sim host running"


def test_killing_the_child_mid_sort_gives_a_typed_error_and_the_service_stays_up(
    tmp_path: Path,
) -> None:
    from tests.service.sim_cell import calibrated_sim_cell

    cell = calibrated_sim_cell(tmp_path, devices_in_child=True)
    arm = cell.devices.arm
    pid = arm.host_pid  # type: ignore[union-attr]
    arm.realtime = True
    arm.motion_trace()
    running = start_in_thread(Service(cell, ServiceConfig(port=0, job_timeout_s=240)))
    try:
        with (
            Client(running.host, running.port, timeout_s=60) as c,
            Client(running.host, running.port, timeout_s=10) as other,
        ):
            rid = c.send("sort")
            _wait_moving(arm, 20)
            os.kill(pid, signal.SIGKILL)
            reply = c.read_reply()
            assert reply["id"] == rid and not reply["ok"], reply
            err = reply["error"]
            assert (err["code"], err["device_code"]) == ("device_error", "device_disconnected")
            assert err["device"].startswith("sim:sorting/"), err
            # The service keeps answering, reports the lost devices, and refuses motion with
            # a typed error at once instead of hanging on a dead process.
            st = other.call("status")
            assert st["ok"], st
            deadline = time.monotonic() + 10
            while st["result"]["devices"]["arm"]["connected"] and time.monotonic() < deadline:
                time.sleep(0.1)
                st = other.call("status")
            assert st["result"]["devices"]["arm"]["connected"] is False, st
            t0 = time.monotonic()
            again = c.call("capture")  # refused at once, not hung on a dead process
            assert again["error"]["device_code"] == "device_disconnected", again
            assert time.monotonic() - t0 < 10
            # reset connects the lost devices again: a fresh child takes the dead one's place
            reset = other.call("reset")
            assert reset["ok"], reset
            assert sorted(reset["result"]["reconnected"]) == ["arm", "camera", "laser"], reset
            assert reset["result"]["lost"] == {}, reset
            fresh = arm.host_pid  # type: ignore[union-attr]
            assert fresh != pid and process_gone(pid)
            assert c.call("capture")["ok"]
            assert other.call("status")["result"]["devices"]["arm"]["connected"] is True
    finally:
        running.stop()
    assert process_gone(pid) and process_gone(fresh)
