"""One blended path on the simulated arm and on the emulated UR controller through the
unmodified ur-rtde client (`movePath`, in its own process, against a virtual cell in its own
process): both end on the target, pass within the blend radius of the via points, beat the
same path with stops, and take the same time. A stop during a blended path ends it within
0.1 s on the simulated arm; a protective stop during one is a typed `safety_stop` through
the UR driver.

Timing tolerance: the path is planned once at `PATH_RATE_HZ` (the planner's 125 Hz) and
stretched to a whole number of periods by the simulator, by less than one step (1/240 s): the
controller's planned duration of the motion it started and the simulator's executed one agree
within 1/240 s. Measured on the controller's clock through ur-rtde, its start and end are read
from its published samples, each within one tick; the emulator's tick runs on the wall clock
and is late under load, so each end also carries the largest gap seen between two published
samples: 1/240 + 2 x (largest gap) s.
"""

from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest

from drivers.base import Waypoint
from drivers.errors import DeviceError, SafetyStopError
from drivers.ur_arm import URArm, URArmConfig
from omnisort_hw.core.kinematics import forward
from sim_backend.sim_arm import SimArm
from sim_backend.sim_cell import SimCell
from sim_backend.virtual_cell.controller import MOVEL_JOINT_CAPS
from tests.sim.virtual_cell_fixture import run_client, virtual_cell

pytest.importorskip("rtde_control", reason="needs ur-rtde")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(240)]

JOINT_V, JOINT_A = 60.0, 120.0  # deg/s, deg/s^2
LIN_V, LIN_A = 250.0, 1200.0  # mm/s, mm/s^2
RADII = (60.0, 40.0)
SIM_STEP_S = 1.0 / 240.0


@pytest.fixture(scope="module")
def vc():
    with virtual_cell(width=128) as cell:
        yield cell


def _sim_arm() -> tuple[SimCell, SimArm]:
    """The in-process simulated arm of the same scene, with the controller's movel joint caps
    (so both plan the linear segment alike)."""
    cell = SimCell.from_scene("sorting", width=64)
    caps = {
        "max_joint_speed_deg_s": MOVEL_JOINT_CAPS[0],
        "max_joint_accel_deg_s2": MOVEL_JOINT_CAPS[1],
    }
    arm = SimArm(cell, max_rates=caps)
    arm.connect()
    return cell, arm


def _waypoints(arm: SimArm, q0: np.ndarray, radii: tuple[float, float]) -> list[Waypoint]:
    via1 = q0 + np.array([30.0, -15.0, 10.0, 0.0, 0.0, 0.0])
    via2 = via1 + np.array([30.0, 15.0, -10.0, 10.0, 0.0, 0.0])
    down = forward(arm.model, via2, arm.tool)
    down[2, 3] -= 80.0
    return [
        Waypoint("joint", via1, JOINT_V, JOINT_A, radii[0]),
        Waypoint("joint", via2, JOINT_V, JOINT_A, radii[1]),
        Waypoint("linear", down, LIN_V, LIN_A),
    ]


def _ur_rows(arm: URArm, path: list[Waypoint]) -> list:
    """The rows the UR driver sends (its own conversion, not a copy of it)."""
    sent: list = []
    arm._link.move_path = lambda rows: sent.extend(rows)  # type: ignore[method-assign]
    arm._follow = lambda *a, **k: None  # type: ignore[method-assign]
    arm.move_path(path)
    return sent


def _controller_run(host: str, rows: list) -> dict:
    out = run_client("tests.sim.ur_rtde_path_client", host, json.dumps(rows))
    assert out["accepted"] and out["start"] is not None and out["end"] is not None, out
    return out


def _sim_run(arm: SimArm, path: list[Waypoint]) -> tuple[float, np.ndarray]:
    world = arm.cell.world
    qs: list[np.ndarray] = []
    step = world.step

    def recording_step(*a, **k):
        step(*a, **k)
        qs.append(world.joints())

    world.step = recording_step  # type: ignore[method-assign]
    t0 = world.sim_time
    try:
        arm.move_path(path)
    finally:
        world.step = step  # type: ignore[method-assign]
    return world.sim_time - t0, np.asarray(qs)


def test_a_blended_path_plays_alike_on_the_sim_arm_and_the_emulated_controller(vc) -> None:
    cell, sim = _sim_arm()
    try:
        ur = URArm(URArmConfig(host=vc.host, poll_period_s=0.01, connect_timeout_s=10.0))
        ur.connect()
        try:
            q0 = ur.joint_positions()
            np.testing.assert_allclose(sim.joint_positions(), q0, atol=1e-6)
            blended = _waypoints(sim, q0, RADII)
            stopped = _waypoints(sim, q0, (0.0, 0.0))
            rows_blended = _ur_rows(ur, blended)
            rows_stopped = _ur_rows(ur, stopped)
        finally:
            ur.close()
        ctl_b = _controller_run(vc.host, rows_blended)
        planned_b = vc.control("status")["last_motion_s"]
        sim_b, q_sim = _sim_run(sim, blended)
        np.testing.assert_allclose(sim.tcp_pose()[:3, 3], blended[-1].target[:3, 3], atol=1e-6)
        sim.move_joints(q0)
        with URArm(URArmConfig(host=vc.host, connect_timeout_s=10.0)) as ur:
            ur.move_joints(q0)
        ctl_s = _controller_run(vc.host, rows_stopped)
        planned_s = vc.control("status")["last_motion_s"]
        sim_s, _ = _sim_run(sim, stopped)
    finally:
        sim.close()
        cell.close()
    ctl_blend_s = ctl_b["end"] - ctl_b["start"]
    ctl_stop_s = ctl_s["end"] - ctl_s["start"]
    print(
        f"blended path: sim {sim_b:.4f} s, controller {ctl_blend_s:.4f} s; "
        f"with stops: sim {sim_s:.4f} s, controller {ctl_stop_s:.4f} s"
    )
    print(f"planned on the controller: blended {planned_b:.4f} s, with stops {planned_s:.4f} s")
    # the same plan on both, blended and stopped
    assert 0.0 <= sim_b - planned_b < SIM_STEP_S and 0.0 <= sim_s - planned_s < SIM_STEP_S
    # the same time on the controller's clock, through ur-rtde
    for measured, sim_time, run in ((ctl_blend_s, sim_b, ctl_b), (ctl_stop_s, sim_s, ctl_s)):
        assert abs(sim_time - measured) <= SIM_STEP_S + 2.0 * run["max_tick_gap"], run
    # quicker than stopping, on both
    assert sim_b < sim_s - 0.1 and ctl_blend_s < ctl_stop_s - 0.1
    # ends on its target (the controller: ur-rtde's 6-digit script text)
    end_tcp = blended[-1].target[:3, 3]
    q_end = np.rad2deg(np.asarray(ctl_b["final_q"]))
    assert np.linalg.norm(forward(sim.model, q_end, sim.tool)[:3, 3] - end_tcp) < 0.1
    # passes within the blend radius of each via point (on both)
    q_ctl = np.rad2deg(np.asarray(ctl_b["q"]))
    for q, name in ((q_sim, "sim"), (q_ctl, "controller")):
        p = forward(sim.model, q, sim.tool)[:, :3, 3]
        sample_gap = float(np.max(np.linalg.norm(np.diff(p, axis=0), axis=1)))
        for w, r in zip(blended[:2], RADII, strict=True):
            via = forward(sim.model, w.target, sim.tool)[:3, 3]
            closest = float(np.min(np.linalg.norm(p - via, axis=1)))
            assert closest <= r + sample_gap, (name, closest, r)


def _path_in_thread(arm, path: list[Waypoint]) -> tuple[threading.Thread, dict]:
    """Run `arm.move_path(path)` on a thread; the box gets the error and when it came."""
    box: dict = {}

    def run() -> None:
        try:
            arm.move_path(path)
        except Exception as exc:
            box["error"], box["t"] = exc, time.monotonic()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, box


def test_stop_during_a_blended_path_on_the_sim_arm_ends_it_within_a_tenth() -> None:
    cell, sim = _sim_arm()
    try:
        q0 = sim.joint_positions()
        path = _waypoints(sim, q0, RADII)
        sim.realtime = True
        thread, box = _path_in_thread(sim, path)
        time.sleep(0.6)
        t_stop = time.monotonic()
        sim.stop()
        thread.join(5.0)
        assert not thread.is_alive()
        assert isinstance(box.get("error"), DeviceError), box
        assert "interrupted by stop" in str(box["error"])
        assert box["t"] - t_stop <= 0.1, box["t"] - t_stop
        held = sim.joint_positions()
        time.sleep(0.2)
        np.testing.assert_array_equal(sim.joint_positions(), held)
        assert np.max(np.abs(held - q0)) > 1.0  # it was under way
    finally:
        sim.close()
        cell.close()


def _ur_path_under_way(vc, ur: URArm) -> tuple[np.ndarray, threading.Thread, dict]:
    """The test path started through the UR driver on a thread, 0.8 s into its motion."""
    q0 = ur.joint_positions()
    cell, sim = _sim_arm()
    try:
        path = _waypoints(sim, q0, RADII)
    finally:
        sim.close()
        cell.close()
    thread, box = _path_in_thread(ur, path)
    time.sleep(0.8)
    assert vc.control("status")["moving"]
    return q0, thread, box


def test_stop_during_a_blended_path_through_the_ur_driver_brakes_the_controller(vc) -> None:
    with URArm(URArmConfig(host=vc.host, poll_period_s=0.01, connect_timeout_s=10.0)) as ur:
        q0, thread, box = _ur_path_under_way(vc, ur)
        t_stop = time.monotonic()
        ur.stop()  # returns once the controller has braked (ur-rtde's stopJ waits for it)
        thread.join(10.0)
        assert isinstance(box.get("error"), DeviceError), box
        assert "interrupted by stop" in str(box["error"])
        # braking from at most 60 deg/s at the driver's 300 deg/s^2: 0.2 s, plus 0.1 s
        brake_s = JOINT_V / ur.config.stop_decel_deg_s2
        assert box["t"] - t_stop <= brake_s + 0.1, box["t"] - t_stop
        deadline = t_stop + brake_s + 0.1
        while vc.control("status")["moving"] and time.monotonic() < deadline:
            time.sleep(0.01)
        assert not vc.control("status")["moving"]
        ur.move_joints(q0)


def test_protective_stop_during_a_blended_path_is_a_typed_safety_stop(vc) -> None:
    with URArm(URArmConfig(host=vc.host, poll_period_s=0.01, connect_timeout_s=10.0)) as ur:
        _, thread, box = _ur_path_under_way(vc, ur)
        t_stop = time.monotonic()
        vc.control("protective_stop")
        thread.join(10.0)
        assert isinstance(box.get("error"), SafetyStopError), box
        assert box["error"].code == "safety_stop" and box["error"].kind == "protective"
        assert box["t"] - t_stop <= 0.1, box["t"] - t_stop
        deadline = time.monotonic() + 2.0
        while vc.control("status")["moving"] and time.monotonic() < deadline:
            time.sleep(0.02)  # the controller brakes to rest
        assert not vc.control("status")["moving"]
        time.sleep(0.3)
        assert vc.dashboard("unlock protective stop") == ["Protective stop releasing"]
