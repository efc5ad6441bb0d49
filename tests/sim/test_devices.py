"""The simulated devices pass the shared device contracts and do what the cell needs."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from drivers.errors import (
    DeviceConfigError,
    DeviceError,
    DeviceTimeoutError,
    SafetyStopError,
)
from omnisort_hw.cell.devices import open_devices as open_cell_devices
from omnisort_hw.core.frames import invert_pose, rot_z
from sim_backend.devices import (
    SimArm,
    SimCamera,
    SimCell,
    SimLaserSwitch,
    SimWristCamera,
    open_devices,
)
from tests.drivers.contract import ArmContract, CameraContract, LaserSwitchContract
from tests.sim.image_measures import redness


@pytest.fixture(scope="module")
def cell() -> SimCell:
    """A small sorting cell (160 px camera) shared by the contract tests of this module."""
    c = SimCell.from_scene("sorting", width=160)
    yield c
    c.close()


class TestSimLaserContract(LaserSwitchContract):
    @pytest.fixture
    def make_laser(self, cell: SimCell):
        return lambda: SimLaserSwitch(cell)


class TestSimCameraContract(CameraContract):
    @pytest.fixture
    def make_camera(self, cell: SimCell):
        return lambda: SimCamera(cell)


class TestSimArmContract(ArmContract):
    @pytest.fixture
    def make_arm(self, cell: SimCell):
        home = np.asarray(cell.scene.robot.home_deg, float)
        cell.world.set_joints(home)
        return lambda: SimArm(cell)


def _down_pose(xyz_B: np.ndarray, yaw_deg: float = 0.0) -> np.ndarray:
    """A TCP pose with the tool pointing down (-Z of B)."""
    T = np.eye(4)
    T[:3, :3] = rot_z(np.radians(yaw_deg)) @ np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = xyz_B
    return T


def test_pick_and_place_puts_the_cube_in_its_bin() -> None:
    cell = SimCell.from_scene("sorting", width=160)
    world = cell.world
    T_B_S = invert_pose(world.T_S_B)
    spec, body = world.info.cubes[0]
    assert spec.color.name == "red"
    c_B = (T_B_S @ world.body_pose(body))[:3, 3]
    bin_S = np.array([-420.0, 1450.0, world.floor_z])  # the red bin of sorting.toml
    bin_B = T_B_S[:3, :3] @ bin_S + T_B_S[:3, 3]
    with SimArm(cell) as arm:
        arm.move_joints([0.0, -90.0, -90.0, -90.0, 90.0, 0.0])
        arm.move_linear(_down_pose(c_B + np.array([0.0, 0.0, 250.0]), spec.yaw_deg))
        arm.move_linear(_down_pose(c_B, spec.yaw_deg), speed_mm_s=100.0)
        np.testing.assert_allclose(arm.tcp_pose()[:3, 3], c_B, atol=0.01)
        arm.gripper.close()
        assert arm.gripper.holding is True and arm.gripper.is_closed
        arm.move_linear(_down_pose(c_B + np.array([0.0, 0.0, 300.0]), spec.yaw_deg))
        lifted = world.body_pose(body)[:3, 3]
        assert lifted[2] > world.floor_z + 300.0  # the cube came up with the gripper
        arm.move_linear(_down_pose(bin_B + np.array([0.0, 0.0, 300.0])))
        arm.gripper.open()
        assert arm.gripper.holding is False
    world.step(240)
    final = world.body_pose(body)[:3, 3]
    inner = 240.0 / 2 - 10.0
    assert np.all(np.abs(final[:2] - bin_S[:2]) < inner)
    assert final[2] < world.floor_z + 120.0  # resting inside, below the rim
    assert world.sim_time > 2.0
    cell.close()


def test_gripper_closing_on_nothing_holds_nothing(cell: SimCell) -> None:
    with SimArm(cell) as arm:
        arm.gripper.close()
        assert arm.gripper.is_closed and arm.gripper.holding is False
        arm.gripper.open()


def test_camera_shows_the_laser_only_when_switched_on() -> None:
    cell = SimCell.from_scene("two_sided", width=320)
    with SimCamera(cell) as cam, SimLaserSwitch(cell) as laser:
        laser.on()
        lit = cam.grab(with_truth=True)
        assert cam.last_truth is not None and cam.last_truth["laser_polylines_px"]
        laser.off()
        dark = cam.grab()
    # At 320 px the 4 mm stripe is narrower than a pixel: compare with the laser-off frame.
    assert ((redness(lit.image) - redness(dark.image)) > 0.05).sum() > 50
    assert redness(dark.image).max() < 0.25
    assert dark.sequence == lit.sequence + 1
    cell.close()


def test_exposure_and_gain_scale_the_image(cell: SimCell) -> None:
    with SimCamera(cell) as cam:
        base = cam.grab().image.astype(float)
        cam.exposure_ms = 5.0
        half = cam.grab().image.astype(float)
        cam.gain = 2.0
        back = cam.grab().image.astype(float)
    mid = (base > 40) & (base < 200)
    assert np.median(half[mid] / base[mid]) == pytest.approx(0.5, abs=0.02)
    assert np.abs(back - base).max() <= 1.0


def test_grab_times_out_with_a_typed_error() -> None:
    cell = SimCell.from_scene("two_sided", width=960)
    with SimCamera(cell) as cam, pytest.raises(DeviceTimeoutError, match="longer than"):
        cam.grab(timeout_s=0.001)
    cell.close()


def test_move_longer_than_its_timeout_is_stopped(cell: SimCell) -> None:
    with SimArm(cell) as arm:
        start = arm.joint_positions()
        target = start + np.array([60.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        with pytest.raises(DeviceTimeoutError, match="timeout"):
            arm.move_joints(target, speed_deg_s=30.0, timeout_s=0.5)
        moved = arm.joint_positions() - start
        assert 2.0 < moved[0] < 30.0  # it moved, then stopped at the timeout
        arm.move_joints(start)


def test_stop_interrupts_a_move_and_stops_block_motion(cell: SimCell) -> None:
    with SimArm(cell) as arm:
        start = arm.joint_positions()
        arm.realtime = True
        timer = threading.Timer(0.3, arm.stop)
        timer.start()
        t0 = time.monotonic()
        with pytest.raises(DeviceError, match="interrupted by stop"):
            arm.move_joints(start + np.array([90.0, 0, 0, 0, 0, 0]), speed_deg_s=45.0)
        assert time.monotonic() - t0 < 1.5
        arm.realtime = False
        arm.trigger_protective_stop()
        assert arm.safety_status().protective_stop
        with pytest.raises(SafetyStopError):
            arm.move_joints(start)
        cell.release_stops()
        arm.move_joints(start)
        np.testing.assert_allclose(arm.joint_positions(), start, atol=1e-6)


def test_wrist_camera_sees_the_cube_below_it() -> None:
    cell = SimCell.from_scene("sorting", width=160)
    world = cell.world
    T_B_S = invert_pose(world.T_S_B)
    spec, body = world.info.cubes[2]
    assert spec.color.name == "blue"
    c_B = (T_B_S @ world.body_pose(body))[:3, 3]
    with SimArm(cell) as arm, SimWristCamera(cell) as wrist:
        arm.move_joints([0.0, -90.0, -90.0, -90.0, 90.0, 0.0])
        arm.move_linear(_down_pose(c_B + np.array([-40.0, 0.0, 350.0])))
        image = wrist.grab().image
    h, w = image.shape[:2]
    centre = image[h // 3 : 2 * h // 3, w // 3 : 2 * w // 3].reshape(-1, 3).mean(axis=0)
    assert centre[0] > centre[1] + 40 and centre[0] > centre[2] + 40  # BGR: blue dominates
    cell.close()


def test_factory_builds_one_cell_for_all_sim_devices() -> None:
    doc = {
        "camera": {"backend": "sim", "scene": "sorting", "width": 160, "seed": 3},
        "laser": {"backend": "sim"},
        "arm": {"backend": "sim", "joint_speed_deg_s": 120.0},
    }
    devices = open_cell_devices(doc)
    assert isinstance(devices.camera, SimCamera)
    assert devices.camera.cell is devices.laser.cell is devices.arm.cell
    assert devices.camera.resolution == (160, 160)
    with devices.camera as cam, devices.laser as laser:
        laser.on()
        assert cam.grab().image.shape == (160, 160, 3)
    devices.camera.cell.close()


@pytest.mark.parametrize(
    ("sections", "key"),
    [
        ({"camera": {"scene": "sorting", "zoom": 2}}, "[camera].zoom"),
        ({"camera": {"width": "big"}}, "[camera].width"),
        ({"camera": {"scene": "sorting"}, "arm": {"scene": "two_sided"}}, "[arm].scene"),
        ({"arm": {"scene": "two_sided"}}, "[arm].scene"),
        ({"camera": {"scene": "no_such_scene"}}, "[camera].scene"),
    ],
)
def test_factory_errors_name_the_key(sections: dict, key: str) -> None:
    with pytest.raises(DeviceConfigError) as info:
        open_devices(sections)
    assert info.value.key == key
    assert str(info.value).startswith(key)


def test_sim_arm_speed_caps_are_configured_like_the_ur_drivers() -> None:
    """`[arm].max_*` caps the simulated arm as it caps the UR driver; a default speed above its
    cap is a configuration error naming the key."""
    with pytest.raises(DeviceConfigError) as info:
        open_devices({"arm": {"scene": "sorting", "max_joint_speed_deg_s": 50.0}})
    assert info.value.key == "[arm].joint_speed_deg_s"
    made = open_devices(
        {"arm": {"scene": "sorting", "joint_speed_deg_s": 40.0, "max_joint_speed_deg_s": 50.0}}
    )
    try:
        assert made["arm"].limits.max_joint_speed_deg_s == 50.0
    finally:
        made["arm"].cell.close()
