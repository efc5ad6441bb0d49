"""The simulated UR arm and its parallel gripper behind `drivers.base.Arm` / `Gripper`: moves
take their planned duration of physics steps, limits and stops as on the real controller."""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from typing import Any

import numpy as np
import pybullet as p
from scipy.spatial.transform import Rotation

from drivers.base import (
    DEFAULT_GRIPPER_TIMEOUT_S,
    DEFAULT_MOVE_TIMEOUT_S,
    RATES,
    Arm,
    Gripper,
    MotionLimits,
    SafetyStatus,
    Waypoint,
    check_path,
)
from drivers.errors import (
    DeviceError,
    DeviceTimeoutError,
    MotionLimitError,
)
from omnisort_hw.core.blended_path import PATH_RATE_HZ, Segment, plan_blended_path, resample
from omnisort_hw.core.frames import invert_pose
from omnisort_hw.core.motion import MotionLimits as PlanLimits
from omnisort_hw.core.motion import Trajectory, plan_joint_move, plan_linear_move
from omnisort_hw.errors import MotionRefusedError
from sim_backend.robot import tcp_pose, tcp_tool
from sim_backend.scene import Scene
from sim_backend.sim_cell import SimCell, _Connectable, _sim_device_error
from sim_backend.world import MM


class SimGripper(Gripper):
    """A parallel gripper that grasps a cube between its fingers with a fixed constraint.

    On close, the cube whose centre lies between the fingers (within the finger length and
    the finger width) and whose size fits the stroke is held: the fingers stop at its faces
    and a fixed constraint ties it to the gripper while the physics steps.
    """

    def __init__(self, arm: SimArm) -> None:
        self.arm = arm
        self._closed = False
        self._constraint: int | None = None
        self._held: int | None = None

    @property
    def is_closed(self) -> bool:
        return self._closed

    @property
    def holding(self) -> bool | None:
        return self._held is not None

    @property
    def held_body(self) -> int | None:
        """pybullet id of the held cube (None when empty)."""
        return self._held

    def _candidate(self) -> tuple[int, float] | None:
        world = self.arm.cell.world
        spec = world.scene.robot
        assert spec is not None and world.arm is not None
        g = spec.gripper
        T_S_grip = world.link_pose(world.arm.body, world.arm.gripper_link)
        T_grip_S = invert_pose(T_S_grip)
        for cube, body in world.info.cubes:
            c = T_grip_S[:3, :3] @ world.body_pose(body)[:3, 3] + T_grip_S[:3, 3]
            half = cube.size_mm / 2.0
            z_lo = g.body_length_mm - half
            z_hi = g.body_length_mm + g.finger_length_mm + half * 0.2
            if (
                cube.size_mm < g.stroke_mm
                and abs(c[0]) < 22.0 + half * 0.5
                and abs(c[1]) < half * 0.5
                and z_lo <= c[2] <= z_hi
            ):
                return body, half
        return None

    def close(self, timeout_s: float = DEFAULT_GRIPPER_TIMEOUT_S) -> None:
        self.arm._require()
        cell = self.arm.cell
        with cell.lock:
            world = cell.world
            assert world.arm is not None
            found = self._candidate()
            if found is None:
                world.set_fingers(0.0)
            else:
                body, half = found
                world.set_fingers(half)
                T_S_grip = world.link_pose(world.arm.body, world.arm.gripper_link)
                T_grip_cube = invert_pose(T_S_grip) @ world.body_pose(body)
                quat = Rotation.from_matrix(T_grip_cube[:3, :3]).as_quat()
                self._constraint = p.createConstraint(
                    world.arm.body,
                    world.arm.gripper_link,
                    body,
                    -1,
                    p.JOINT_FIXED,
                    [0.0, 0.0, 0.0],
                    list(T_grip_cube[:3, 3] * MM),
                    [0.0, 0.0, 0.0],
                    list(quat),
                    [0.0, 0.0, 0.0, 1.0],
                    physicsClientId=world.client,
                )
                p.changeConstraint(self._constraint, maxForce=2000.0, physicsClientId=world.client)
                self._held = body
            world.step(int(0.2 / world.time_step))
            self._closed = True

    def open(self, timeout_s: float = DEFAULT_GRIPPER_TIMEOUT_S) -> None:
        self.arm._require()
        cell = self.arm.cell
        with cell.lock:
            world = cell.world
            spec = world.scene.robot
            assert spec is not None
            if self._constraint is not None:
                p.removeConstraint(self._constraint, physicsClientId=world.client)
                self._constraint = None
                self._held = None
            world.set_fingers(spec.gripper.stroke_mm / 2.0)
            world.step(int(0.2 / world.time_step))
            self._closed = False


# `[arm]` keys of the simulated arm that set its highest speeds and accelerations.
MAX_RATES = frozenset(f"max_{name}" for name in RATES)


def _default_workspace(scene: Scene) -> MotionLimits:
    robot = scene.robot
    assert robot is not None
    reach = 1100.0 if robot.model.lower() != "ur10e" else 1500.0
    return MotionLimits(
        workspace_min_mm=(-reach, -reach, -robot.pedestal_mm + 5.0),
        workspace_max_mm=(reach, reach, reach),
    )


class SimArm(_Connectable, Arm):
    """The UR arm of the scene: joint and linear moves planned by the core (`core.motion`),
    executed one physics step (1/240 s) per trajectory sample."""

    _kind = "arm"

    def __init__(
        self,
        cell: SimCell,
        joint_speed_deg_s: float | None = None,
        joint_accel_deg_s2: float = 120.0,
        linear_speed_mm_s: float | None = None,
        linear_accel_mm_s2: float = 1000.0,
        limits: MotionLimits | None = None,
        realtime: bool = False,
        max_rates: dict[str, Any] | None = None,
    ) -> None:
        super().__init__(cell)
        robot = cell.scene.robot
        if robot is None or cell.world.arm is None:
            raise _sim_device_error(
                "[arm].scene",
                f"scene {cell.scene.name!r} has no [robot] section; a sim arm needs one",
            )
        self.robot = robot
        self.model = cell.world.ur
        self.tool = tcp_tool(robot.gripper.tcp_offset_mm)
        self.joint_speed = float(joint_speed_deg_s or robot.joint_speed_deg_s)
        self.joint_accel = float(joint_accel_deg_s2)
        self.linear_speed = float(linear_speed_mm_s or robot.linear_speed_mm_s)
        self.linear_accel = float(linear_accel_mm_s2)
        self._limits = replace(limits or _default_workspace(cell.scene), **(max_rates or {}))
        for name, value in (
            ("joint_speed_deg_s", self.joint_speed),
            ("joint_accel_deg_s2", self.joint_accel),
            ("linear_speed_mm_s", self.linear_speed),
            ("linear_accel_mm_s2", self.linear_accel),
        ):
            try:
                self._limits.check_rate(name, None, value)
            except MotionLimitError as exc:
                raise _sim_device_error(f"[arm].{name}", str(exc)) from None
        self.realtime = realtime
        self._gripper = SimGripper(self)
        self._stop = threading.Event()

    @property
    def limits(self) -> MotionLimits:
        return self._limits

    @property
    def gripper(self) -> SimGripper:
        return self._gripper

    def joint_positions(self) -> np.ndarray:
        self._require()
        with self.cell.lock:
            return self.cell.world.joints()

    def tcp_pose(self) -> np.ndarray:
        self._require()
        with self.cell.lock:
            return tcp_pose(self.model, self.cell.world.joints(), self.robot.gripper.tcp_offset_mm)

    def safety_status(self) -> SafetyStatus:
        self._require()
        c = self.cell
        mode = "RUNNING" if not (c.protective_stop or c.emergency_stop) else "IDLE"
        return SafetyStatus(c.protective_stop, c.emergency_stop, mode)

    def trigger_protective_stop(self) -> None:
        """Emulate a protective stop (as a collision would cause on the real arm)."""
        self.cell.protective_stop = True
        self._stop.set()

    def stop(self) -> None:
        self._stop.set()

    def _plan_limits(
        self, joint_speed: float, joint_accel: float, lin_speed: float, lin_accel: float
    ) -> PlanLimits:
        rate = 1.0 / self.cell.world.time_step
        return PlanLimits(
            joint_speed_deg_s=joint_speed,
            joint_acc_deg_s2=joint_accel,
            linear_speed_mm_s=lin_speed,
            linear_acc_mm_s2=lin_accel,
            rate_hz=rate,
        )

    def move_joints(
        self,
        q_deg: object,
        speed_deg_s: float | None = None,
        accel_deg_s2: float | None = None,
        timeout_s: float = DEFAULT_MOVE_TIMEOUT_S,
    ) -> None:
        self._require()
        q = self._limits.check_joints(q_deg)
        v = self._limits.check_rate("joint_speed_deg_s", speed_deg_s, self.joint_speed)
        a = self._limits.check_rate("joint_accel_deg_s2", accel_deg_s2, self.joint_accel)
        self.safety_status().raise_if_stopped(self.name)
        limits = self._plan_limits(v, a, self.linear_speed, self.linear_accel)
        try:
            traj = plan_joint_move(self.joint_positions(), q, limits, model=self.model)
        except (MotionRefusedError, ValueError) as exc:
            raise MotionLimitError(f"{self.name}: joint move refused: {exc}") from None
        self._execute(traj, timeout_s, "joint move")

    def move_linear(
        self,
        pose: object,
        speed_mm_s: float | None = None,
        accel_mm_s2: float | None = None,
        timeout_s: float = DEFAULT_MOVE_TIMEOUT_S,
    ) -> None:
        self._require()
        T = self._limits.check_pose(pose)
        v = self._limits.check_rate("linear_speed_mm_s", speed_mm_s, self.linear_speed)
        a = self._limits.check_rate("linear_accel_mm_s2", accel_mm_s2, self.linear_accel)
        self.safety_status().raise_if_stopped(self.name)
        # As a UR's movel: the tool's speed and acceleration, the joints' maxima only.
        lim = self._limits
        limits = self._plan_limits(lim.max_joint_speed_deg_s, lim.max_joint_accel_deg_s2, v, a)
        try:
            traj = plan_linear_move(self.model, self.joint_positions(), T, limits, tool=self.tool)
        except (MotionRefusedError, ValueError) as exc:
            raise MotionLimitError(f"{self.name}: linear move refused: {exc}") from None
        self._execute(traj, timeout_s, "linear move")

    def segment(self, w: Waypoint) -> Segment:
        """The core's segment for a checked waypoint: the limits `move_joints` or
        `move_linear` would plan that move with (a linear move: the joints' maxima)."""
        lim = self._limits
        if w.kind == "joint":
            v = lim.check_rate("joint_speed_deg_s", w.speed, self.joint_speed)
            a = lim.check_rate("joint_accel_deg_s2", w.accel, self.joint_accel)
            limits = self._plan_limits(v, a, self.linear_speed, self.linear_accel)
        else:
            v = lim.check_rate("linear_speed_mm_s", w.speed, self.linear_speed)
            a = lim.check_rate("linear_accel_mm_s2", w.accel, self.linear_accel)
            limits = self._plan_limits(lim.max_joint_speed_deg_s, lim.max_joint_accel_deg_s2, v, a)
        return Segment(w.kind, np.asarray(w.target, float), limits, w.blend_mm)

    def move_path(self, path: object, timeout_s: float = DEFAULT_MOVE_TIMEOUT_S) -> None:
        """The core's blended path (`core.blended_path`, planned at its own rate and played
        one physics step per sample), as the emulated controller plays a ur-rtde path."""
        self._require()
        segments = [self.segment(w) for w in check_path(self._limits, path)]
        self.safety_status().raise_if_stopped(self.name)
        try:
            planned = plan_blended_path(
                self.model, self.joint_positions(), segments, tool=self.tool, rate_hz=PATH_RATE_HZ
            )
        except (MotionRefusedError, ValueError) as exc:
            raise MotionLimitError(f"{self.name}: path refused: {exc}") from None
        traj = resample(planned.trajectory, 1.0 / self.cell.world.time_step)
        self._execute(traj, timeout_s, "blended path")

    def _execute(self, traj: Trajectory, timeout_s: float, what: str) -> None:
        """Step the trajectory through the physics; honour stop(), stops and the timeout."""
        self._stop.clear()
        world = self.cell.world
        start_wall = time.monotonic()
        for k in range(1, len(traj)):
            if self._stop.is_set():
                self.safety_status().raise_if_stopped(self.name)
                raise DeviceError(f"{self.name}: {what} interrupted by stop()", device=self.name)
            if traj.t[k] > timeout_s:
                raise DeviceTimeoutError(
                    f"{self.name}: {what} needs {traj.duration:.1f} s, more than the timeout "
                    f"of {timeout_s:.1f} s; the arm was stopped (raise the timeout or the speed)",
                    device=self.name,
                )
            with self.cell.lock:
                world.set_joints(traj.q[k])
                world.step()
            if self.realtime:
                lag = traj.t[k] - (time.monotonic() - start_wall)
                if lag > 0:
                    time.sleep(lag)
