"""The real UR driver (`URArm` -> `RTDELink` -> ur-rtde in its worker process) against the
virtual cell: the arm contract, and the faults a real cell has (protective stop during a move,
the controller killed mid-move, a stalled controller), each ending in its typed error within
its timeout."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from drivers.errors import (
    DeviceDisconnectedError,
    DeviceError,
    DeviceTimeoutError,
    SafetyStopError,
)
from drivers.ur_arm import URArm, URArmConfig
from tests.drivers.contract import ArmContract
from tests.sim.ur_rtde_client import wait_until
from tests.sim.virtual_cell_fixture import virtual_cell

pytest.importorskip("rtde_control", reason="needs ur-rtde")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]

FAST = {
    "poll_period_s": 0.01,
    "gripper_settle_s": 0.0,
    "reconnect_backoff_s": 0.05,
    "connect_timeout_s": 10.0,
}


def make_arm(host: str, **overrides: object) -> URArm:
    return URArm(URArmConfig(host=host, **{**FAST, **overrides}))  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def vc():
    with virtual_cell(width=128) as cell:
        yield cell


class TestURArmOnVirtualCell(ArmContract):
    joint_tolerance_deg = 0.01
    position_tolerance_mm = 0.1

    @pytest.fixture
    def make_arm(self, vc):
        return lambda: make_arm(vc.host)


def _move_in_thread(fn) -> tuple[threading.Thread, dict]:
    box: dict = {}

    def run() -> None:
        t0 = time.monotonic()
        try:
            fn()
            box["result"] = "finished"
        except Exception as exc:
            box["error"] = exc
        box["seconds"] = time.monotonic() - t0

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, box


def test_protective_stop_during_a_move_is_safety_stop_and_nothing_is_resent(vc) -> None:
    with make_arm(vc.host) as arm:
        start = arm.joint_positions()
        target = start + np.array([40.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        thread, box = _move_in_thread(lambda: arm.move_joints(target, speed_deg_s=20.0))
        time.sleep(0.6)
        vc.control("protective_stop")
        thread.join(10.0)
        assert isinstance(box.get("error"), SafetyStopError), box
        assert box["error"].kind == "protective" and box["error"].code == "safety_stop"
        assert wait_until(lambda: not vc.control("status")["moving"], timeout_s=10.0), (
            "still braking"
        )
        stopped = vc.control("status")  # the controller braked to rest
        assert stopped["safety_mode"] == "PROTECTIVE_STOP" and not stopped["moving"]
        with pytest.raises(SafetyStopError):
            arm.move_joints(start)
        time.sleep(0.3)
        assert vc.dashboard("unlock protective stop") == ["Protective stop releasing"]
        motions = vc.control("status")["motions"]
        time.sleep(1.0)
        after = vc.control("status")
        assert after["motions"] == motions and not after["moving"], "a motion was resent"
        np.testing.assert_allclose(after["q_deg"], stopped["q_deg"], atol=1e-9)
        arm.move_joints(start)
        np.testing.assert_allclose(arm.joint_positions(), start, atol=0.01)


def test_stalled_controller_gives_device_timeout(vc) -> None:
    with make_arm(vc.host, state_timeout_s=0.5, call_timeout_s=2.0) as arm:
        start = arm.joint_positions()
        vc.control("stall", what="arm", seconds=3.0)
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeoutError) as info:
            for _ in range(200):
                arm.joint_positions()
                time.sleep(0.01)
        assert time.monotonic() - t0 < 2.5
        assert info.value.code == "device_timeout"
        time.sleep(3.0)
    with make_arm(vc.host) as arm:
        np.testing.assert_allclose(arm.joint_positions(), start, atol=1e-6)


def test_controller_killed_mid_move_is_device_disconnected_within_the_timeout() -> None:
    with virtual_cell(width=64) as doomed:
        arm = make_arm(doomed.host, reconnect_attempts=1)
        arm.connect()
        try:
            target = arm.joint_positions() + np.array([40.0, 0.0, 0.0, 0.0, 0.0, 0.0])
            thread, box = _move_in_thread(lambda: arm.move_joints(target, speed_deg_s=20.0))
            time.sleep(0.5)
            t_kill = time.monotonic()
            doomed.kill()
            thread.join(15.0)
            seen_after = time.monotonic() - t_kill
            print(f"controller killed mid-move -> {box.get('error')!r} after {seen_after:.2f} s")
            assert not thread.is_alive(), "the move hung after the controller died"
            assert isinstance(box.get("error"), DeviceDisconnectedError), box
            assert box["error"].code == "device_disconnected"
            # within one call timeout (the worker's own bound), not ur-rtde's reconnect loop
            assert seen_after < arm.config.call_timeout_s + 1.0, seen_after
            with pytest.raises(DeviceDisconnectedError):
                arm.joint_positions()
        finally:
            arm.close()


def test_emergency_stop_then_power_on_and_brake_release(vc) -> None:
    from drivers.errors import DeviceNotReadyError

    with make_arm(vc.host) as arm:
        start = arm.joint_positions()
        target = start + np.array([0.0, 0.0, 0.0, 0.0, 0.0, 40.0])
        thread, box = _move_in_thread(lambda: arm.move_joints(target, speed_deg_s=20.0))
        time.sleep(0.5)
        vc.control("emergency_stop")
        thread.join(10.0)
        assert isinstance(box.get("error"), SafetyStopError), box
        assert box["error"].kind == "emergency"
        vc.control("release_emergency_stop")
        # the next RTDE package carries it; the bound is generous for a loaded machine
        assert wait_until(lambda: not arm.safety_status().emergency_stop, timeout_s=10.0), (
            "e-stop still set"
        )
        with pytest.raises(DeviceNotReadyError):
            arm.move_joints(start)
        assert vc.dashboard("power on", "brake release", "robotmode") == [
            "Powering on",
            "Brake releasing",
            "Robotmode: RUNNING",
        ]
        assert wait_until(lambda: arm.safety_status().robot_mode == "RUNNING", timeout_s=10.0), (
            "not RUNNING"
        )
        arm.move_joints(start)
        np.testing.assert_allclose(arm.joint_positions(), start, atol=0.01)


def test_dropped_connection_reconnects_without_moving(vc) -> None:
    with make_arm(vc.host) as arm:
        before = arm.joint_positions()
        motions = vc.control("status")["motions"]
        assert vc.control("drop", what="arm")["closed"] >= 1
        deadline = time.monotonic() + 10.0
        while True:  # the driver reconnects with back-off; a read may fail meanwhile
            try:
                now = arm.joint_positions()
                break
            except (DeviceDisconnectedError, DeviceTimeoutError):
                assert time.monotonic() < deadline, "no reconnect within 10 s"
                time.sleep(0.2)
        np.testing.assert_allclose(now, before, atol=1e-9)
        assert vc.control("status")["motions"] == motions, "a motion was resent"
        target = before + np.array([2.0, 0, 0, 0, 0, 0])
        try:  # ur-rtde may still be re-establishing its own connection: then this one is lost
            arm.move_joints(target)
        except DeviceDisconnectedError:
            assert vc.control("status")["motions"] == motions
            time.sleep(0.5)
            arm.move_joints(target)
        np.testing.assert_allclose(arm.joint_positions(), target, atol=0.01)


def test_a_move_that_ur_rtde_refuses_is_a_device_error_and_the_link_stays(vc) -> None:
    """ur-rtde checks a move's speed itself (at most 3.14 rad/s) and raises ValueError: the
    worker answers with a typed DeviceError naming the controller and keeps its session, where
    it once died of it and the move came back as "connection lost"."""
    with make_arm(vc.host) as arm:
        before = arm.joint_positions()
        motions = vc.control("status")["motions"]
        q = list(np.radians(before + np.array([2.0, 0, 0, 0, 0, 0])))
        with pytest.raises(DeviceError) as info:
            arm._link.move_j(q, 3.2, 1.0)  # past the URArmConfig caps, straight to the link
        assert not isinstance(info.value, DeviceDisconnectedError), info.value
        assert "3.14" in str(info.value) and vc.host in str(info.value), info.value
        assert arm._link.is_connected()
        assert vc.control("status")["motions"] == motions, "a refused move reached the arm"
        target = before + np.array([2.0, 0, 0, 0, 0, 0])
        arm.move_joints(target, speed_deg_s=179.9)  # the cap itself goes through
        np.testing.assert_allclose(arm.joint_positions(), target, atol=0.01)
