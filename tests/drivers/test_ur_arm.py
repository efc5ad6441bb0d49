"""UR arm driver above the `URLink` boundary, against a recording stand-in with fault injection.

These tests prove unit conversion, the order of checks (limits before anything is sent),
safety stops, timeouts, drops and reconnects, and the gripper output with injected faults;
`test_virtual_cell_arm.py` runs the same driver through ur-rtde against the virtual cell.
"""

from __future__ import annotations

import logging
import socket
import time

import numpy as np
import pytest

from drivers.base import pose_matrix
from drivers.errors import (
    BadReplyError,
    DeviceConfigError,
    DeviceDisconnectedError,
    DeviceError,
    DeviceNotFoundError,
    DeviceNotReadyError,
    DeviceTimeoutError,
    MotionLimitError,
    SafetyStopError,
)
from drivers.ur_arm import URArm, URArmConfig, tcp_matrix_from_ur, ur_pose_from_matrix
from drivers.ur_rtde_adapter import RTDELink, probe_rtde
from tests.drivers.contract import ArmContract
from tests.drivers.ur_standin import HOME_POSE, HOME_Q, RecordingURLink

pytestmark = pytest.mark.timeout(20)

FAST = {"poll_period_s": 0.001, "gripper_settle_s": 0.0, "reconnect_backoff_s": 0.01}


def make(link: RecordingURLink | None = None, **overrides: object) -> tuple[URArm, RecordingURLink]:
    link = link or RecordingURLink()
    settings: dict[str, object] = {"host": "10.0.0.2", **FAST}
    settings.update(overrides)
    return URArm(URArmConfig(**settings), link=link), link  # type: ignore[arg-type]


@pytest.fixture
def arm_and_link():
    arm, link = make()
    arm.connect()
    yield arm, link
    arm.close()


class TestURArmContract(ArmContract):
    @pytest.fixture
    def make_arm(self):
        return lambda: make()[0]


def test_joint_positions_are_degrees_of_the_controllers_radians(arm_and_link) -> None:
    arm, _ = arm_and_link
    np.testing.assert_allclose(arm.joint_positions(), np.rad2deg(HOME_Q))


def test_tcp_pose_is_mm_matrix_of_the_controllers_metres_and_rotvec(arm_and_link) -> None:
    arm, _ = arm_and_link
    T = arm.tcp_pose()
    np.testing.assert_allclose(T[:3, 3], np.array(HOME_POSE[:3]) * 1000.0)
    expected = pose_matrix(np.array(HOME_POSE[:3]) * 1000, np.rad2deg(HOME_POSE[3:]))
    np.testing.assert_allclose(T, expected, atol=1e-9)


def test_pose_conversion_round_trips() -> None:
    ur = [0.41, -0.2, 0.33, 0.3, -1.2, 2.0]
    np.testing.assert_allclose(ur_pose_from_matrix(tcp_matrix_from_ur(ur)), ur, atol=1e-12)


def test_move_joints_sends_radians_and_configured_speed(arm_and_link) -> None:
    arm, link = arm_and_link
    target = np.array([10.0, -80.0, 70.0, -90.0, -90.0, 5.0])
    arm.move_joints(target)
    ((name, (q, speed, accel)),) = link.motion_calls()
    assert name == "move_j"
    np.testing.assert_allclose(q, np.deg2rad(target))
    assert speed == pytest.approx(np.deg2rad(arm.config.joint_speed_deg_s))
    assert accel == pytest.approx(np.deg2rad(arm.config.joint_accel_deg_s2))


def test_move_linear_sends_metres_and_rotation_vector(arm_and_link) -> None:
    arm, link = arm_and_link
    T = pose_matrix([350.0, -120.0, 300.0], [0.0, 180.0, 0.0])
    arm.move_linear(T, speed_mm_s=100.0, accel_mm_s2=500.0)
    ((name, (pose, speed, accel)),) = link.motion_calls()
    assert name == "move_l"
    np.testing.assert_allclose(pose[:3], [0.35, -0.12, 0.30])
    assert np.linalg.norm(pose[3:]) == pytest.approx(np.pi)
    assert (speed, accel) == (pytest.approx(0.1), pytest.approx(0.5))


@pytest.mark.parametrize(
    "call",
    [
        lambda arm: arm.move_joints([400.0, 0, 0, 0, 0, 0]),
        lambda arm: arm.move_joints([0, 0, 0, 0, 0]),
        lambda arm: arm.move_joints([0, 0, 0, 0, 0, float("nan")]),
        lambda arm: arm.move_joints([0, 0, 0, 0, 0, 0], speed_deg_s=1000.0),
        lambda arm: arm.move_joints([0, 0, 0, 0, 0, 0], accel_deg_s2=-1.0),
        lambda arm: arm.move_linear(pose_matrix([2000.0, 0, 300], [0, 180, 0])),
        lambda arm: arm.move_linear(pose_matrix([300.0, 0, -500], [0, 180, 0])),
        lambda arm: arm.move_linear(pose_matrix([300.0, 0, 300], [0, 180, 0]), speed_mm_s=5000),
        lambda arm: arm.move_linear(np.eye(3)),
        lambda arm: arm.move_linear(np.diag([1.0, 1.0, -1.0, 1.0])),
    ],
    ids=[
        "joint-limit",
        "five-joints",
        "nan",
        "joint-speed",
        "joint-accel",
        "x-outside-box",
        "z-below-box",
        "linear-speed",
        "not-4x4",
        "reflection",
    ],
)
def test_bad_targets_are_refused_before_anything_reaches_the_controller(call) -> None:
    arm, link = make()
    arm.connect()
    link.calls.clear()
    with pytest.raises(MotionLimitError, match="nothing sent"):
        call(arm)
    assert link.calls == []


def test_limits_come_from_the_configuration() -> None:
    arm, link = make(joint_min_deg=[-90.0] * 6, joint_max_deg=[90.0] * 6)
    arm.connect()
    link.calls.clear()
    with pytest.raises(MotionLimitError, match=r"joint 1 = 100\.00 deg not in"):
        arm.move_joints([100.0, 0, 0, 0, 0, 0])
    assert link.calls == []


@pytest.mark.parametrize(
    ("inject", "kind"),
    [
        (RecordingURLink.protective_stop, "protective"),
        (RecordingURLink.emergency_stop, "emergency"),
    ],
)
def test_a_stop_before_the_move_is_raised_and_nothing_is_sent(inject, kind) -> None:
    arm, link = make()
    arm.connect()
    inject(link)
    with pytest.raises(SafetyStopError) as info:
        arm.move_joints(np.rad2deg(HOME_Q) + 1.0)
    assert info.value.kind == kind
    assert info.value.code == "safety_stop"
    assert "10.0.0.2" in str(info.value)
    assert link.motion_calls() == []
    status = arm.safety_status()
    assert (status.protective_stop, status.emergency_stop) == (
        kind == "protective",
        kind == "emergency",
    )


@pytest.mark.parametrize(("mode", "kind"), [(3, "protective"), (7, "emergency")])
def test_a_stop_during_the_move_is_raised_promptly(mode: int, kind: str) -> None:
    arm, link = make(RecordingURLink(move_polls=1000))
    arm.connect()
    link.stop_after_polls = (5, mode)
    t0 = time.monotonic()
    with pytest.raises(SafetyStopError) as info:
        arm.move_joints(np.rad2deg(HOME_Q) + 1.0, timeout_s=5.0)
    assert info.value.kind == kind
    assert time.monotonic() - t0 < 1.0


def test_robot_not_running_is_not_ready() -> None:
    arm, link = make()
    arm.connect()
    link.robot_mode_value = 5
    with pytest.raises(DeviceNotReadyError, match="IDLE"):
        arm.move_joints(np.rad2deg(HOME_Q))
    assert link.motion_calls() == []


def test_a_move_that_does_not_finish_is_stopped_at_the_timeout(arm_and_link) -> None:
    arm, link = arm_and_link
    link.hang_moves = True
    t0 = time.monotonic()
    with pytest.raises(DeviceTimeoutError, match="stopped"):
        arm.move_joints(np.rad2deg(HOME_Q) + 1.0, timeout_s=0.2)
    elapsed = time.monotonic() - t0
    assert 0.2 <= elapsed < 0.7
    assert link.names()[-1] == "stop_j"


def test_a_move_that_ends_away_from_the_target_is_an_error(arm_and_link) -> None:
    arm, link = arm_and_link
    real_move = link.move_j

    def short_move(q: list[float], speed: float, accel: float) -> None:
        real_move([v + 0.01 for v in q], speed, accel)

    link.move_j = short_move  # type: ignore[method-assign]
    with pytest.raises(DeviceError, match="from the target"):
        arm.move_joints(np.rad2deg(HOME_Q) + 1.0, timeout_s=3.0)


def test_dropped_connection_during_a_move_is_raised_and_not_resumed(caplog) -> None:
    caplog.set_level(logging.WARNING, logger="drivers.arm")
    arm, link = make(RecordingURLink(move_polls=1000))
    arm.connect()
    link.drop_after_polls = 3
    with pytest.raises(DeviceDisconnectedError):
        arm.move_joints(np.rad2deg(HOME_Q) + 1.0, timeout_s=5.0)
    assert len(link.motion_calls()) == 1
    link.drop_after_polls = None
    link._target = None
    q = arm.joint_positions()  # reconnects, reads, does not move
    np.testing.assert_allclose(q, np.rad2deg(HOME_Q))
    assert "reconnect" in link.names()
    assert len(link.motion_calls()) == 1, "a reconnect must never resend the interrupted move"
    assert any("reconnected; the arm was not moved" in r.getMessage() for r in caplog.records)


def test_reconnect_gives_up_after_the_configured_attempts(arm_and_link) -> None:
    arm, link = arm_and_link
    link.drop()
    link.refuse_reconnect = True
    t0 = time.monotonic()
    with pytest.raises(DeviceDisconnectedError, match="3 reconnect attempts failed"):
        arm.joint_positions()
    assert link.names().count("reconnect") == 3
    assert time.monotonic() - t0 < 1.0


def test_unreachable_controller_is_device_not_found() -> None:
    link = RecordingURLink()
    link.reachable = False
    arm, _ = make(link)
    with pytest.raises(DeviceNotFoundError):
        arm.connect()
    assert not arm.is_connected


def test_stop_is_sent_even_in_a_protective_stop(arm_and_link) -> None:
    arm, link = arm_and_link
    link.protective_stop()
    arm.stop()
    assert link.names()[-1] == "stop_j"


def test_stop_with_the_link_down_says_so(arm_and_link) -> None:
    arm, link = arm_and_link
    link.drop()
    with pytest.raises(DeviceDisconnectedError, match="cannot send stop"):
        arm.stop()


def test_gripper_drives_the_configured_output_and_level() -> None:
    arm, link = make(gripper_io="standard", gripper_pin=3, gripper_closed_level=False)
    arm.connect()
    arm.gripper.close()
    assert link.outputs[("standard", 3)] is False
    assert arm.gripper.is_closed
    arm.gripper.open()
    assert link.outputs[("standard", 3)] is True
    assert not arm.gripper.is_closed
    assert arm.gripper.holding is None


def test_gripper_sense_input_reports_holding() -> None:
    arm, link = make(gripper_sense_pin=1)
    arm.connect()
    link.inputs[("tool", 1)] = True
    assert arm.gripper.holding is True
    link.inputs[("tool", 1)] = False
    assert arm.gripper.holding is False


def test_gripper_output_that_does_not_read_back_times_out() -> None:
    arm, link = make()
    arm.connect()
    link.output = lambda kind, pin: False  # type: ignore[method-assign]
    t0 = time.monotonic()
    with pytest.raises(DeviceTimeoutError, match="gripper_pin"):
        arm.gripper.close(timeout_s=0.1)
    assert time.monotonic() - t0 < 0.5


@pytest.mark.parametrize(
    ("settings", "key"),
    [
        ({"host": ""}, "host"),
        ({"joint_min_deg": [0.0] * 5}, "joint_min_deg"),
        ({"workspace_min_mm": [0, 0, 500], "workspace_max_mm": [1, 1, 100]}, "workspace_min_mm"),
        ({"gripper_io": "tool", "gripper_pin": 2}, "gripper_pin"),
        ({"joint_speed_deg_s": 500.0}, "joint_speed_deg_s"),
        # ur-rtde sends at most 3.14 rad/s (179.9 deg/s): a cap of 180 would let a move pass
        # here that ur-rtde then refuses.
        ({"max_joint_speed_deg_s": 180.0}, "max_joint_speed_deg_s"),
        ({"max_linear_speed_mm_s": 3500.0}, "max_linear_speed_mm_s"),
        ({"poll_period_s": 0}, "poll_period_s"),
    ],
)
def test_bad_settings_name_the_key(settings: dict[str, object], key: str) -> None:
    with pytest.raises(DeviceConfigError) as info:
        URArmConfig(**settings)  # type: ignore[arg-type]
    assert info.value.key == f"[arm].{key}"


def test_real_adapter_reports_nothing_listening_without_ur_rtde() -> None:
    """The real adapter's first step (a TCP probe) fails fast and typed when nothing listens."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.monotonic()
    with pytest.raises(DeviceNotFoundError, match=f"127.0.0.1:{port}"):
        probe_rtde("127.0.0.1", 1.0, port=port)
    assert time.monotonic() - t0 < 1.0


def _one_shot_peer(reply: bytes | None) -> tuple[socket.socket, int]:
    """A TCP peer on 127.0.0.1 that answers the first request with `reply` (None: never)."""
    import threading

    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen()

    def serve() -> None:
        conn, _ = listener.accept()
        with conn:
            conn.recv(16)
            if reply is not None:
                conn.sendall(reply)
            time.sleep(1.0)

    threading.Thread(target=serve, daemon=True).start()
    return listener, listener.getsockname()[1]


def test_real_adapter_probe_times_out_on_a_peer_that_never_answers() -> None:
    listener, port = _one_shot_peer(None)
    with listener:
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeoutError, match="no RTDE answer"):
            probe_rtde("127.0.0.1", 0.3, port=port)
        assert time.monotonic() - t0 < 0.8


def test_real_adapter_probe_rejects_a_peer_that_is_not_rtde() -> None:
    listener, port = _one_shot_peer(b"HTTP/1.1 400 Bad Request\r\n\r\n")
    with listener, pytest.raises(BadReplyError, match="not a UR RTDE server"):
        probe_rtde("127.0.0.1", 1.0, port=port)


def test_real_adapter_probe_accepts_an_rtde_protocol_answer() -> None:
    listener, port = _one_shot_peer(b"\x00\x04V\x01")
    with listener:
        probe_rtde("127.0.0.1", 1.0, port=port)


def test_real_adapter_calls_before_open_are_typed() -> None:
    with pytest.raises(DeviceDisconnectedError):
        RTDELink().actual_q()
