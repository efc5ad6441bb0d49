"""The simulated cell hosted in a child process (`sim_backend.device_host` / `device_proxies`):
the proxies behave as the in-process devices, stop reaches a move in the child within one
physics step, a killed or hung child is a typed error naming the device (never a hang), and
closing the devices leaves no process behind."""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.base import Arm, Camera, LaserSwitch
from drivers.errors import DeviceConfigError, DeviceDisconnectedError, DeviceTimeoutError
from tests.service.procs import process_gone

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
pytestmark = pytest.mark.timeout(180)

WIDTH = 160


def _open(**host: Any) -> dict[str, Any]:
    from sim_backend.device_proxies import open_devices

    sections = {
        "camera": {"scene": "sorting", "width": WIDTH, "height": WIDTH, "degraded": True},
        "laser": {},
        "arm": {},
    }
    made = open_devices(sections, None, **host)
    for dev in made.values():
        dev.connect()
    return made


def _close(made: dict[str, Any]) -> None:
    for dev in made.values():
        dev.close()


def test_proxies_do_what_the_in_process_devices_do_and_close_ends_the_child() -> None:
    from omnisort_hw.core.pick_planning import SortConfig
    from sim_backend.devices import open_devices as open_in_process
    from sim_backend.sort_harness import scene_of

    made = _open()
    cam, laser, arm = made["camera"], made["laser"], made["arm"]
    pid = arm.host_pid
    assert pid != os.getpid()
    try:
        assert isinstance(cam, Camera) and isinstance(laser, LaserSwitch) and isinstance(arm, Arm)
        ref = open_in_process({"camera": {"scene": "sorting", "width": WIDTH, "height": WIDTH}})
        assert cam.resolution == ref["camera"].resolution == (WIDTH, WIDTH)
        assert cam.serial == ref["camera"].serial
        # The sensor's settings are the child's: set here, read back from there.
        cam.set_exposure_ms(4.0)
        assert cam.get_exposure_ms() == 4.0 and cam.exposure_ms == 4.0
        cam.set_pixel_format("BGR3")
        assert cam.pixel_format == "BGR3"
        laser.off()
        assert laser.state() is False
        dark = cam.grab(with_truth=True)
        laser.on()
        assert laser.state() is True
        lit = cam.grab()
        assert dark.image.shape == (WIDTH, WIDTH, 3) and dark.image.dtype == np.uint8
        assert lit.sequence == dark.sequence + 1
        assert {"camera", "laser_plane", "robot_base"} <= set(cam.last_truth)
        assert cam.clean_image().shape == (WIDTH, WIDTH, 3)
        assert cam.direct_laser.shape == (WIDTH, WIDTH)
        q0 = arm.joint_positions()
        np.testing.assert_allclose(q0, arm.cell.scene.robot.home_deg)
        target = q0 + np.array([20.0, 0, 0, 0, 0, 0])
        arm.move_joints(target)
        np.testing.assert_allclose(arm.joint_positions(), target, atol=1e-6)
        assert arm.state().safety.ok and arm.gripper.held_body is None
        # The scene for `[sorting] from_scene` and the verifier work through the proxies.
        scene = scene_of(made)
        assert scene is not None
        assert len(scene.sort_config(SortConfig()).bins) == len(arm.cell.scene.bins)
        verifier = scene.verifier()
        assert len(verifier.true_cubes()) == len(arm.cell.scene.cubes)
    finally:
        _close(made)
    assert process_gone(pid), "the sim host outlived its devices"
    assert not arm.is_connected
    with pytest.raises(DeviceDisconnectedError, match="sim:sorting/arm"):
        arm.joint_positions()


def _moving(arm: Any, dq: list[float], samples: int) -> tuple[threading.Thread, list]:
    """A paced joint move by `dq` on a thread of its own, returned once the child has carried
    out `samples` motion samples; the list receives what the move raised."""
    arm.realtime = True  # paced to the wall clock, as a real arm moves
    arm.motion_trace()  # start recording
    q = arm.joint_positions() + np.asarray(dq, float)
    raised: list[BaseException] = []

    def move() -> None:
        try:
            arm.move_joints(q)
        except BaseException as exc:
            raised.append(exc)

    mover = threading.Thread(target=move)
    mover.start()
    deadline = time.monotonic() + 30
    while arm.motion_trace()["samples"] < samples:
        assert time.monotonic() < deadline, "the arm never moved"
        time.sleep(0.01)
    return mover, raised


def test_stop_reaches_a_move_in_the_child_within_one_physics_step() -> None:
    made = _open()
    arm = made["arm"]
    try:
        period = arm.cell.read("world.time_step")
        mover, outcome = _moving(arm, [90.0, 0, 0, 0, 0, 0], 60)
        assert arm.realtime is True  # set in the child
        requested = arm.motion_trace()["now"]
        arm.stop()
        mover.join(30)
        assert not mover.is_alive()
        trace = arm.motion_trace()
    finally:
        _close(made)
    assert outcome and "interrupted by stop" in str(outcome[0]), outcome
    assert trace["stops"], "the stop never reached the arm"
    # At most the step in progress when the stop arrived; and well inside the 0.1 s.
    assert trace["last_sample"] - trace["stops"][0] <= period + 1e-9, trace
    assert trace["last_sample"] - requested <= 0.1, (trace, requested)


def test_a_killed_child_is_a_typed_error_naming_the_device_never_a_hang() -> None:
    made = _open()
    cam, arm = made["camera"], made["arm"]
    pid = arm.host_pid
    try:
        mover, caught = _moving(arm, [0.0, 0, 0, 0, 0, 90.0], 10)
        os.kill(pid, signal.SIGKILL)
        mover.join(15)
        assert not mover.is_alive(), "the move's caller hung on a dead child"
        assert isinstance(caught[0], DeviceDisconnectedError), caught
        assert "sim:sorting/arm" in str(caught[0]) and "exit code -9" in str(caught[0])
        with pytest.raises(DeviceDisconnectedError, match="sim:sorting/camera"):
            cam.grab()
        assert not arm.is_connected and not cam.is_connected
        arm.stop()  # never refused: nothing moves in a process that is gone
        arm.connect()  # connected again: a fresh child, a new cell from the same settings
        fresh = arm.host_pid
        assert fresh != pid and arm.is_connected and not cam.is_connected
        assert np.asarray(arm.joint_positions()).shape == (6,)
        cam.connect()
        assert cam.grab().image.ndim == 3
    finally:
        _close(made)
    assert process_gone(pid) and process_gone(fresh)


def test_a_hung_child_is_a_device_timeout_and_is_ended() -> None:
    made = _open(call_timeout_s=1.0)
    arm = made["arm"]
    pid = arm.host_pid
    try:
        os.kill(pid, signal.SIGSTOP)
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeoutError, match="sim:sorting/arm"):
            arm.joint_positions()
        assert time.monotonic() - t0 < 10  # the call's timeout, not forever
        assert process_gone(pid), "a hung child must be ended"
        with pytest.raises(DeviceDisconnectedError):
            made["laser"].state()
    finally:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, signal.SIGCONT)
        _close(made)


def test_configuration_errors_in_the_child_stay_typed_and_leave_no_child() -> None:
    import multiprocessing

    from sim_backend.device_proxies import open_devices

    with pytest.raises(DeviceConfigError) as err:
        open_devices({"camera": {"scene": "no_such_scene"}})
    assert err.value.key == "[camera].scene"
    with pytest.raises(DeviceConfigError, match=r"\[arm\]\.speed"):
        open_devices({"arm": {"speed": 3.0}})  # refused before any child starts
    assert not [p for p in multiprocessing.active_children() if p.name == "omnisort-sim-host"]


ORPHAN_SCRIPT = """
import sys, time
from sim_backend.device_proxies import open_devices

if __name__ == "__main__":
    made = open_devices({"laser": {}})
    made["laser"].connect()
    print(made["laser"].host_pid, flush=True)
    time.sleep(120)
"""


def test_the_child_ends_when_its_parent_is_killed(tmp_path: Path) -> None:
    import subprocess
    import sys

    script = tmp_path / "parent.py"
    script.write_text(ORPHAN_SCRIPT)
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": str(root)}
    parent = subprocess.Popen(
        [sys.executable, str(script)], stdout=subprocess.PIPE, text=True, env=env, cwd=root
    )
    try:
        line = parent.stdout.readline()  # type: ignore[union-attr]
        assert line.strip().isdigit(), f"the parent did not start its sim host: {line!r}"
        child = int(line)
        parent.kill()
        parent.wait(10)
        # The child sees the end of its pipe, closes the world and exits (reaped by init).
        assert process_gone(child, within_s=20), "the sim host outlived its killed parent"
    finally:
        parent.kill()
        parent.wait(10)
