"""Shared contract tests for every implementation of the device interfaces in `drivers.base`.

Each class here is a set of pytest tests that any implementation (real driver or simulated
device) must pass. To apply one, subclass it in a `test_*.py` module and provide the factory
fixture it names; the factory returns a NEW, NOT YET CONNECTED device each time it is called:

    from tests.drivers.contract import LaserSwitchContract

    class TestSimLaser(LaserSwitchContract):
        @pytest.fixture
        def make_laser(self):
            return lambda: SimLaser(...)

* `LaserSwitchContract`  needs `make_laser`.
* `CameraContract`       needs `make_camera` (a source with at least 4 frames).
* `ArmContract`          needs `make_arm`; override `joint_target` / `linear_target` if the
                         default small moves from the current position do not suit the arm.

The classes do not start with `Test`, so pytest collects them only through subclasses.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import pytest

from drivers.base import (
    RATES,
    Arm,
    Camera,
    Frame,
    Gripper,
    LaserSwitch,
    MotionLimits,
    SafetyStatus,
    Waypoint,
)
from drivers.errors import DeviceError, MotionLimitError


def _assert_error_is_typed(exc: DeviceError) -> None:
    assert isinstance(exc.code, str) and exc.code
    assert str(exc), "a device error must carry a message"


class LaserSwitchContract:
    """What every `LaserSwitch` does."""

    @pytest.fixture
    def make_laser(self) -> Callable[[], LaserSwitch]:
        raise NotImplementedError("subclasses provide make_laser")

    @pytest.fixture
    def laser(self, make_laser: Callable[[], LaserSwitch]):
        device = make_laser()
        device.connect()
        yield device
        device.close()

    def test_connect_sets_is_connected_and_is_idempotent(self, make_laser) -> None:
        device = make_laser()
        assert not device.is_connected
        device.connect()
        try:
            assert device.is_connected
            device.connect()
            assert device.is_connected
        finally:
            device.close()
        assert not device.is_connected
        device.close()
        assert not device.is_connected

    def test_context_manager_connects_and_closes(self, make_laser) -> None:
        with make_laser() as device:
            assert device.is_connected
            device.off()
        assert not device.is_connected

    def test_on_reads_back_on(self, laser: LaserSwitch) -> None:
        laser.on()
        assert laser.state() is True

    def test_off_reads_back_off(self, laser: LaserSwitch) -> None:
        laser.on()
        laser.off()
        assert laser.state() is False

    def test_set_is_idempotent_and_toggles(self, laser: LaserSwitch) -> None:
        for wanted in (True, True, False, False, True, False):
            laser.set(wanted)
            assert laser.state() is wanted

    def test_accepts_an_explicit_timeout(self, laser: LaserSwitch) -> None:
        laser.set(True, timeout_s=2.0)
        assert laser.state(timeout_s=2.0) is True

    def test_use_after_close_is_a_typed_error(self, make_laser) -> None:
        device = make_laser()
        device.connect()
        device.close()
        with pytest.raises(DeviceError) as info:
            device.on()
        _assert_error_is_typed(info.value)

    def test_name_identifies_the_device(self, laser: LaserSwitch) -> None:
        assert isinstance(laser.name, str) and laser.name


class CameraContract:
    """What every `Camera` does."""

    @pytest.fixture
    def make_camera(self) -> Callable[[], Camera]:
        raise NotImplementedError("subclasses provide make_camera")

    @pytest.fixture
    def camera(self, make_camera: Callable[[], Camera]):
        device = make_camera()
        device.connect()
        yield device
        device.close()

    def test_connect_and_close_are_idempotent(self, make_camera) -> None:
        device = make_camera()
        assert not device.is_connected
        device.connect()
        device.connect()
        assert device.is_connected
        device.close()
        device.close()
        assert not device.is_connected

    def test_grab_returns_a_bgr_frame_of_the_stated_resolution(self, camera: Camera) -> None:
        frame = camera.grab()
        assert isinstance(frame, Frame)
        assert frame.image.dtype == np.uint8
        assert frame.image.ndim == 3 and frame.image.shape[2] == 3
        w, h = camera.resolution
        assert frame.image.shape[:2] == (h, w)

    def test_frames_have_increasing_sequence_and_monotonic_timestamps(self, camera: Camera) -> None:
        t0 = time.monotonic()
        frames = [camera.grab() for _ in range(3)]
        t1 = time.monotonic()
        seqs = [f.sequence for f in frames]
        assert seqs == sorted(seqs) and len(set(seqs)) == 3
        stamps = [f.timestamp for f in frames]
        assert stamps == sorted(stamps)
        assert t0 - 1.0 <= stamps[0] and stamps[-1] <= t1 + 1e-3
        assert abs(frames[-1].wall_time - time.time()) < 5.0

    def test_grab_accepts_a_timeout(self, camera: Camera) -> None:
        frame = camera.grab(timeout_s=5.0)
        assert frame.image.size > 0

    def test_serial_is_a_stable_identifier(self, make_camera) -> None:
        first = make_camera()
        with first:
            serial = first.serial
        assert isinstance(serial, str) and serial
        with make_camera() as second:
            assert second.serial == serial

    def test_grab_after_close_is_a_typed_error(self, make_camera) -> None:
        device = make_camera()
        device.connect()
        device.close()
        with pytest.raises(DeviceError) as info:
            device.grab(timeout_s=1.0)
        _assert_error_is_typed(info.value)

    def test_exposure_and_gain_work_or_say_clearly_they_cannot(self, camera: Camera) -> None:
        for setter, getter, value in (
            (camera.set_exposure_ms, camera.get_exposure_ms, 5.0),
            (camera.set_gain, camera.get_gain, 2.0),
        ):
            try:
                setter(value)
            except DeviceError as exc:
                _assert_error_is_typed(exc)
                continue
            assert getter() == pytest.approx(value, rel=0.2)
        assert camera.grab().image.size > 0


class ArmContract:
    """What every `Arm` does (units: mm, degrees, 4x4 TCP pose)."""

    joint_tolerance_deg = 0.5
    position_tolerance_mm = 2.0

    @pytest.fixture
    def make_arm(self) -> Callable[[], Arm]:
        raise NotImplementedError("subclasses provide make_arm")

    @pytest.fixture
    def arm(self, make_arm: Callable[[], Arm]):
        device = make_arm()
        device.connect()
        yield device
        device.close()

    def joint_target(self, arm: Arm) -> np.ndarray:
        """A reachable joint target near the current position (override if needed)."""
        return arm.joint_positions() + np.array([5.0, -5.0, 5.0, 0.0, 0.0, 5.0])

    def linear_target(self, arm: Arm) -> np.ndarray:
        """A reachable TCP pose near the current one (override if needed)."""
        T = arm.tcp_pose().copy()
        T[:3, 3] += np.array([20.0, 0.0, 20.0])
        return T

    def test_connect_and_close_are_idempotent(self, make_arm) -> None:
        device = make_arm()
        device.connect()
        device.connect()
        assert device.is_connected
        device.close()
        device.close()
        assert not device.is_connected

    def test_joint_positions_are_six_degrees(self, arm: Arm) -> None:
        q = arm.joint_positions()
        assert q.shape == (6,) and np.all(np.isfinite(q))

    def test_tcp_pose_is_a_rigid_transform_in_mm(self, arm: Arm) -> None:
        T = arm.tcp_pose()
        assert T.shape == (4, 4)
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-6)
        np.testing.assert_allclose(T[3], [0, 0, 0, 1])
        assert np.linalg.norm(T[:3, 3]) > 10.0, "translation looks like metres, not millimetres"

    def test_safety_status_is_reported(self, arm: Arm) -> None:
        status = arm.safety_status()
        assert isinstance(status, SafetyStatus)
        assert status.ok and isinstance(status.robot_mode, str)

    def test_limits_are_exposed(self, arm: Arm) -> None:
        assert isinstance(arm.limits, MotionLimits)

    def test_move_joints_reaches_the_target(self, arm: Arm) -> None:
        target = self.joint_target(arm)
        arm.move_joints(target, timeout_s=30.0)
        np.testing.assert_allclose(arm.joint_positions(), target, atol=self.joint_tolerance_deg)

    def test_move_linear_reaches_the_target(self, arm: Arm) -> None:
        target = self.linear_target(arm)
        arm.move_linear(target, timeout_s=30.0)
        np.testing.assert_allclose(
            arm.tcp_pose()[:3, 3], target[:3, 3], atol=self.position_tolerance_mm
        )

    def test_joint_target_outside_limits_is_refused_without_moving(self, arm: Arm) -> None:
        before = arm.joint_positions()
        bad = before.copy()
        bad[0] = arm.limits.joint_max_deg[0] + 10.0
        with pytest.raises(MotionLimitError):
            arm.move_joints(bad)
        np.testing.assert_allclose(arm.joint_positions(), before, atol=1e-6)

    def test_pose_outside_workspace_is_refused_without_moving(self, arm: Arm) -> None:
        before = arm.tcp_pose()
        bad = before.copy()
        bad[2, 3] = arm.limits.workspace_max_mm[2] + 100.0
        with pytest.raises(MotionLimitError):
            arm.move_linear(bad)
        np.testing.assert_allclose(arm.tcp_pose(), before, atol=1e-6)

    @pytest.mark.parametrize("name", sorted(RATES))
    def test_rate_above_the_configured_maximum_is_refused_without_moving(
        self, arm: Arm, name: str
    ) -> None:
        """The contract states the limits: a speed or acceleration above `[arm].max_*` (or not
        positive) is refused with the same error, whatever the arm."""
        cap = getattr(arm.limits, f"max_{name}")
        assert np.isfinite(cap) and cap > 0
        kind, arg = name.split("_", 1)  # "joint", "speed_deg_s"
        before = arm.joint_positions()
        for value in (cap * 1.5, 0.0, float("nan")):
            with pytest.raises(MotionLimitError) as info:
                if kind == "joint":
                    arm.move_joints(self.joint_target(arm), **{arg: value})
                else:
                    arm.move_linear(self.linear_target(arm), **{arg: value})
            assert info.value.code == "motion_refused"
            assert f"[arm].max_{name}" in str(info.value), str(info.value)
        np.testing.assert_allclose(arm.joint_positions(), before, atol=1e-6)

    def test_move_path_ends_on_its_last_waypoint(self, arm: Arm) -> None:
        via = self.joint_target(arm)
        T = arm.tcp_pose().copy()
        end = self.joint_target(arm) + np.array([5.0, 0.0, -5.0, 0.0, 0.0, 0.0])
        path = [Waypoint("joint", via, blend_mm=10.0), Waypoint("joint", end)]
        arm.move_path(path, timeout_s=30.0)
        np.testing.assert_allclose(arm.joint_positions(), end, atol=self.joint_tolerance_deg)
        T[:3, 3] += np.array([0.0, 20.0, 10.0])
        arm.move_path([Waypoint("linear", T)], timeout_s=30.0)
        np.testing.assert_allclose(arm.tcp_pose()[:3, 3], T[:3, 3], atol=self.position_tolerance_mm)

    def test_path_with_a_bad_waypoint_is_refused_without_moving(self, arm: Arm) -> None:
        before = arm.joint_positions()
        bad = before.copy()
        bad[0] = arm.limits.joint_max_deg[0] + 10.0
        good = self.joint_target(arm)
        for path in (
            [Waypoint("joint", good, blend_mm=10.0), Waypoint("joint", bad)],
            [Waypoint("joint", good, blend_mm=-1.0), Waypoint("joint", before)],
            [Waypoint("joint", good, blend_mm=float("nan")), Waypoint("joint", before)],
            [Waypoint("joint", good, speed=arm.limits.max_joint_speed_deg_s * 2.0)],
            [],
        ):
            with pytest.raises(MotionLimitError) as info:
                arm.move_path(path)
            assert info.value.code == "motion_refused"
        np.testing.assert_allclose(arm.joint_positions(), before, atol=1e-6)

    def test_stop_when_idle_is_harmless(self, arm: Arm) -> None:
        arm.stop()
        assert arm.safety_status().ok

    def test_gripper_closes_and_opens(self, arm: Arm) -> None:
        gripper = arm.gripper
        assert isinstance(gripper, Gripper)
        gripper.close()
        assert gripper.is_closed is True
        gripper.open()
        assert gripper.is_closed is False
        assert gripper.holding in (True, False, None)
