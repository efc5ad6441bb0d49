"""Simulated devices behind the `drivers.base` interfaces, sharing one simulated cell.

    cell = SimCell.from_scene("sorting")
    with SimCamera(cell) as cam, SimLaserSwitch(cell) as laser, SimArm(cell) as arm:
        laser.on()
        frame = cam.grab()                          # renders the world's current state
        arm.move_joints(q)                          # bounded speed, physics stepped at 240 Hz
        arm.move_linear(T_base_tcp)                 # straight line, analytic IK (core)
        arm.gripper.close()                         # grasps a cube between the fingers

`open_devices(sections, base_dir)` is the factory `omnisort_hw.devices` calls for
`backend = "sim"`: every sim device of one cell configuration shares one `SimCell`.
Time in the simulator is simulated time: a move takes its planned duration of physics
steps (as fast as the computer goes, or paced to the wall clock with `realtime = true`), and
a move that would outlast its timeout is stopped there and raises `DeviceTimeoutError`.
"""

from __future__ import annotations

import threading
import time
import weakref
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p
from scipy.spatial.transform import Rotation

from drivers.base import (
    DEFAULT_GRIPPER_TIMEOUT_S,
    DEFAULT_MOVE_TIMEOUT_S,
    RATES,
    Arm,
    Camera,
    Frame,
    Gripper,
    LaserSwitch,
    MotionLimits,
    SafetyStatus,
)
from drivers.errors import (
    DeviceConfigError,
    DeviceDisconnectedError,
    DeviceError,
    DeviceTimeoutError,
    MotionLimitError,
)
from omnisort_hw.core.frames import homogeneous, invert_pose
from omnisort_hw.core.motion import MotionLimits as PlanLimits
from omnisort_hw.core.motion import Trajectory, plan_joint_move, plan_linear_move
from omnisort_hw.errors import ConfigError, MotionRefusedError
from sim_backend.exposed_frames import ExposedFrames, world_state_key
from sim_backend.hostile_light import Lighting, apply_to_scene, lighting
from sim_backend.robot import tcp_pose, tcp_tool
from sim_backend.scene import Scene, load_scene, sized
from sim_backend.scene_images import camera_model_for, render_world
from sim_backend.sensor import NOMINAL_EXPOSURE_MS, PIXEL_FORMATS, Exposure
from sim_backend.world import MM, SimWorld

DEFAULT_SIM_GRAB_TIMEOUT_S = 60.0


class SimCell:
    """One simulated world (scene, pybullet, camera model) shared by the sim devices.

    Every access to pybullet goes through `lock`. The world lives as long as the cell
    (`close()` or garbage collection disconnects pybullet).
    """

    def __init__(self, scene: Scene, seed: int = 0, light: Lighting | None = None) -> None:
        self.lighting = light or Lighting()
        scene = apply_to_scene(scene, self.lighting)
        self.scene = scene
        self.seed = int(seed)
        self.world = SimWorld(scene)
        self.model = camera_model_for(scene)
        self.lock = threading.RLock()
        self.protective_stop = False
        self.emergency_stop = False
        self._finalizer = weakref.finalize(self, self.world.close)

    @classmethod
    def from_scene(
        cls, scene: Scene | str | Path, seed: int = 0, light: str = "normal", **camera: Any
    ) -> SimCell:
        """A cell from a scene (object, file or shipped name) under the named lighting
        (`sim_backend.hostile_light`); `camera` overrides [camera] keys (e.g. width=640,
        height=640: the cube-map face size scales along)."""
        sc = scene if isinstance(scene, Scene) else load_scene(scene)
        width, height = camera.pop("width", None), camera.pop("height", None)
        sc = sized(sc, width, height)
        if camera:
            sc = sc.replace(camera=camera)
        return cls(sc, seed, lighting(light))

    @property
    def name(self) -> str:
        """ "sim:SCENE", used in device names."""
        return f"sim:{self.scene.name}"

    def render(
        self,
        seed: int,
        degraded: bool,
        brightness: float = 1.0,
        with_truth: bool = False,
        laser_on: bool | None = None,
    ) -> tuple[np.ndarray, dict[str, Any] | None]:
        """Render the current state (BGR uint8) and optionally its truth."""
        with self.lock:
            return render_world(
                self.world,
                self.model,
                seed=seed,
                degraded=degraded,
                laser_on=laser_on,
                with_truth=with_truth,
                brightness=brightness,
            )

    def bump_camera(self, angle_deg: float, axis: str | Sequence[float] = "x") -> np.ndarray:
        """Turn the camera on its mount by `angle_deg` about `axis` of S ("x", "y", "z" or a
        vector) from where it is now, as a knock would; returns the new R_SC. The drift
        watchdog's test subject: renders and truth follow the turned camera."""
        named = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
        ax = np.asarray(named[axis] if isinstance(axis, str) and axis in named else axis, float)
        if ax.shape != (3,) or not np.linalg.norm(ax) > 0 or not np.isfinite(angle_deg):
            raise ValueError(f"camera bump: axis must be x, y, z or a 3-vector, got {axis!r}")
        turn = Rotation.from_rotvec(np.radians(angle_deg) * ax / np.linalg.norm(ax)).as_matrix()
        with self.lock:
            self.world.R_SC = turn @ self.world.R_SC
            return self.world.R_SC.copy()

    def release_stops(self) -> None:
        """Clear protective and emergency stops (the pendant's job on a real cell)."""
        self.protective_stop = False
        self.emergency_stop = False

    def close(self) -> None:
        """Disconnect pybullet now."""
        self._finalizer()


class _Connectable:
    """Shared life cycle of the sim devices."""

    _kind = "device"

    def __init__(self, cell: SimCell) -> None:
        self.cell = cell
        self._connected = False

    @property
    def name(self) -> str:
        return f"{self.cell.name}/{self._kind}"

    @property
    def is_connected(self) -> bool:
        return self._connected

    def connect(self) -> None:
        self._connected = True

    def close(self) -> None:
        self._connected = False

    def _require(self) -> None:
        if not self._connected:
            raise DeviceDisconnectedError(
                f"{self.name} is not connected (call connect() or use it in a with block)",
                device=self.name,
            )


class SimCamera(_Connectable, Camera):
    """The fisheye on the boom: each grab shows the world as it is (laser as switched).

    Clean mode: each grab renders; exposure and gain scale the brightness (10 ms and gain 1
    are nominal). With `degraded`, the sensor of `sim_backend.sensor` exposes every frame
    from a render cached per world state: exposure and gain change signal and noise, the
    well and the ADC clip, the lamps flicker, noise is drawn anew per frame, and the pixel
    format decides the chroma (MJPG 4:2:0, YUYV 4:2:2, BGR3 full).
    """

    _kind = "camera"

    def __init__(
        self,
        cell: SimCell,
        degraded: bool = False,
        exposure_ms: float = NOMINAL_EXPOSURE_MS,
        gain: float = 1.0,
        grab_timeout_s: float = DEFAULT_SIM_GRAB_TIMEOUT_S,
        bump: tuple[float, str, int] | None = None,
        pixel_format: str = "MJPG",
    ) -> None:
        super().__init__(cell)
        # (angle deg, axis, after this many grabs): the mount is knocked once, between grabs.
        self.bump = bump
        self.degraded = degraded
        self._format = str(pixel_format)
        if self._format not in PIXEL_FORMATS:
            raise _sim_device_error("[camera].pixel_format", f"one of {PIXEL_FORMATS}")
        self._frames: ExposedFrames | None = None
        self._clean: tuple[Any, np.ndarray, dict | None] | None = None
        self._draws = 0
        self._exposure_ms = float(exposure_ms)
        self._gain = float(gain)
        self.grab_timeout_s = float(grab_timeout_s)
        self._sequence = 0
        self._pool: ThreadPoolExecutor | None = None
        self.last_truth: dict[str, Any] | None = None

    def connect(self) -> None:
        if not self._connected:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="simcam")
            self._sequence = 0
        super().connect()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
        super().close()

    @property
    def resolution(self) -> tuple[int, int]:
        return (self.cell.scene.camera.width, self.cell.scene.camera.height)

    @property
    def tone_curve(self) -> str:
        """The curve the scene renders with (`[render] tone_curve`)."""
        return self.cell.scene.render.tone_curve

    @property
    def serial(self) -> str:
        cam = self.cell.scene.camera
        model = cam.model_file or f"equidistant{cam.fov_deg:g}"
        return f"SIM-{self.cell.scene.name}-{cam.width}x{cam.height}-{model}"

    @property
    def direct_laser(self) -> np.ndarray | None:
        """(H, W) the renderer's laser light of the last degraded render (truth: where the
        laser lights the scene directly), None before one."""
        return self._frames.direct_laser if self._frames is not None else None

    @property
    def pixel_formats(self) -> tuple[str, ...]:
        return PIXEL_FORMATS if self.degraded else ()

    @property
    def pixel_format(self) -> str:
        return self._format if self.degraded else ""

    def set_pixel_format(self, fourcc: str) -> None:
        if fourcc not in self.pixel_formats:
            super().set_pixel_format(fourcc)
        self._format = fourcc

    def get_exposure_ms(self) -> float:
        return self._exposure_ms

    def set_exposure_ms(self, exposure_ms: float) -> None:
        if not (np.isfinite(exposure_ms) and 0.01 <= exposure_ms <= 1000.0):
            raise DeviceError(
                f"{self.name}: exposure {exposure_ms} ms outside [0.01, 1000]", device=self.name
            )
        self._exposure_ms = float(exposure_ms)

    def get_gain(self) -> float:
        return self._gain

    def set_gain(self, gain: float) -> None:
        if not (np.isfinite(gain) and 0.1 <= gain <= 16.0):
            raise DeviceError(f"{self.name}: gain {gain} outside [0.1, 16]", device=self.name)
        self._gain = float(gain)

    def _render(self, sequence: int, with_truth: bool) -> tuple[np.ndarray, dict | None]:
        if self.degraded:
            with self.cell.lock:
                if self._frames is None:
                    cell = self.cell
                    self._frames = ExposedFrames(cell.world, cell.model, cell.seed, cell.lighting)
                settings = Exposure(
                    self._exposure_ms,
                    self._gain,
                    bool(self.cell.world.laser_on),
                    self.cell.lighting.flicker_depth,
                    self._format,
                )
                self._draws += 1
                return self._frames.frame(settings, self._draws, with_truth)
        brightness = self._exposure_ms / NOMINAL_EXPOSURE_MS * self._gain
        with self.cell.lock:
            # A clean frame depends only on the state: the same state renders the same bytes.
            key = (world_state_key(self.cell.world), self.cell.world.laser_on, brightness)
            if (
                self._clean is not None
                and self._clean[0] == key
                and (self._clean[2] or not with_truth)
            ):
                return self._clean[1], self._clean[2]
            image, truth = self.cell.render(
                self.cell.seed + sequence, self.degraded, brightness, with_truth=with_truth
            )
            self._clean = (key, image, truth)
            return image, truth

    def grab(self, timeout_s: float | None = None, with_truth: bool = False) -> Frame:
        """Render a fresh frame; `with_truth` also keeps its ground truth in `last_truth`."""
        self._require()
        assert self._pool is not None
        timeout = self.grab_timeout_s if timeout_s is None else float(timeout_s)
        self._sequence += 1
        seq = self._sequence
        if self.bump is not None and seq > self.bump[2]:
            self.cell.bump_camera(self.bump[0], self.bump[1])
            self.bump = None
        future = self._pool.submit(self._render, seq, with_truth)
        try:
            image, truth = future.result(timeout=timeout)
        except FutureTimeout:
            raise DeviceTimeoutError(
                f"{self.name}: rendering the frame took longer than {timeout:.1f} s (a smaller "
                "image or face size renders faster)",
                device=self.name,
            ) from None
        if with_truth:
            self.last_truth = truth
        return Frame.now(image, seq)


class SimLaserSwitch(_Connectable, LaserSwitch):
    """The laser's switch: the next grab shows the stripe when on."""

    _kind = "laser"

    def set(self, on: bool, timeout_s: float | None = None) -> None:
        self._require()
        with self.cell.lock:
            self.cell.world.laser_on = bool(on)

    def state(self, timeout_s: float | None = None) -> bool:
        self._require()
        return bool(self.cell.world.laser_on)


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
        max_rates: dict[str, float] | None = None,
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


def _sim_device_error(key: str, message: str) -> DeviceConfigError:
    return DeviceConfigError(f"{key}: {message}", key=key)


_KEYS: dict[str, dict[str, type]] = {
    "camera": {
        "scene": str,
        "seed": int,
        "degraded": bool,
        "width": int,
        "height": int,
        "model_file": str,
        "exposure_ms": float,
        "gain": float,
        "grab_timeout_s": float,
        "bump_deg": float,
        "bump_axis": str,
        "bump_after_grabs": int,
        "pixel_format": str,
        "lighting": str,
    },
    "laser": {"scene": str, "seed": int},
    "arm": {
        "scene": str,
        "seed": int,
        "joint_speed_deg_s": float,
        "joint_accel_deg_s2": float,
        "linear_speed_mm_s": float,
        "linear_accel_mm_s2": float,
        "max_joint_speed_deg_s": float,
        "max_joint_accel_deg_s2": float,
        "max_linear_speed_mm_s": float,
        "max_linear_accel_mm_s2": float,
        "realtime": bool,
    },
}


def _check_settings(kind: str, settings: dict[str, Any]) -> dict[str, Any]:
    allowed = _KEYS.get(kind)
    if allowed is None:
        raise _sim_device_error(f"[{kind}].backend", f'no simulated "{kind}" device')
    out: dict[str, Any] = {}
    for key, value in settings.items():
        if key not in allowed:
            raise _sim_device_error(
                f"[{kind}].{key}",
                f"unknown key for the simulated {kind} (known: {', '.join(sorted(allowed))})",
            )
        tp = allowed[key]
        ok = isinstance(value, tp) and not (tp is int and isinstance(value, bool))
        if tp is float and isinstance(value, int) and not isinstance(value, bool):
            value, ok = float(value), True
        if not ok:
            raise _sim_device_error(f"[{kind}].{key}", f"expected {tp.__name__}, got {value!r}")
        out[key] = value
    return out


def open_devices(
    sections: dict[str, dict[str, Any]], base_dir: Path | None = None
) -> dict[str, Camera | LaserSwitch | Arm]:
    """Build the `backend = "sim"` devices of a cell configuration, unconnected, on one cell.

    `sections` maps "camera" / "laser" / "arm" to their settings. Keys: `scene` (a scene file,
    relative to `base_dir`, or a shipped scene name; default "sorting"), `seed`; camera:
    `degraded`, `width`, `height`, `model_file` (camera.json), `exposure_ms`, `gain`,
    `grab_timeout_s`, `pixel_format` (MJPG, YUYV, BGR3), `lighting` (a hostile-light
    scenario of `sim_backend.hostile_light`, for the whole cell), `bump_deg`/`bump_axis`/
    `bump_after_grabs` (the mount is knocked once by that angle about that axis of S after that
    many grabs); arm: `joint_speed_deg_s`, `joint_accel_deg_s2`, `linear_speed_mm_s`,
    `linear_accel_mm_s2`, their caps `max_joint_speed_deg_s`, `max_joint_accel_deg_s2`,
    `max_linear_speed_mm_s`, `max_linear_accel_mm_s2` (as the UR driver's), `realtime`.
    """
    checked = {kind: _check_settings(kind, dict(s)) for kind, s in sections.items()}
    scenes = {(k, s["scene"]) for k, s in checked.items() if "scene" in s}
    names = {name for _, name in scenes}
    if len(names) > 1:
        kind = sorted(scenes)[0][0]
        raise _sim_device_error(
            f"[{kind}].scene", f"the simulated devices must share one scene, got {sorted(names)}"
        )
    scene_name = next(iter(names)) if names else "sorting"
    path = Path(scene_name)
    if base_dir is not None and not path.is_absolute() and (base_dir / path).exists():
        path = base_dir / path
    seeds = {s["seed"] for s in checked.values() if "seed" in s}
    cam = checked.get("camera", {})
    overrides = {k: cam[k] for k in ("width", "height") if k in cam}
    if "model_file" in cam:
        mf = Path(cam["model_file"])
        overrides["model_file"] = str(base_dir / mf if base_dir and not mf.is_absolute() else mf)
    try:
        cell = SimCell.from_scene(
            path, seed=min(seeds) if seeds else 0, light=cam.get("lighting", "normal"), **overrides
        )
    except ValueError as exc:
        raise _sim_device_error("[camera].lighting", str(exc)) from None
    except ConfigError as exc:
        key = next((f"[{k}].scene" for k, s in checked.items() if "scene" in s), "[camera].scene")
        raise _sim_device_error(key, str(exc)) from None
    made: dict[str, Camera | LaserSwitch | Arm] = {}
    if "camera" in checked:
        made["camera"] = SimCamera(
            cell,
            degraded=cam.get("degraded", False),
            exposure_ms=cam.get("exposure_ms", NOMINAL_EXPOSURE_MS),
            gain=cam.get("gain", 1.0),
            grab_timeout_s=cam.get("grab_timeout_s", DEFAULT_SIM_GRAB_TIMEOUT_S),
            bump=(
                (cam["bump_deg"], cam.get("bump_axis", "x"), cam.get("bump_after_grabs", 0))
                if "bump_deg" in cam
                else None
            ),
            pixel_format=cam.get("pixel_format", "MJPG"),
        )
    if "laser" in checked:
        made["laser"] = SimLaserSwitch(cell)
    if "arm" in checked:
        arm = checked["arm"]
        made["arm"] = SimArm(
            cell,
            joint_speed_deg_s=arm.get("joint_speed_deg_s"),
            joint_accel_deg_s2=arm.get("joint_accel_deg_s2", 120.0),
            linear_speed_mm_s=arm.get("linear_speed_mm_s"),
            linear_accel_mm_s2=arm.get("linear_accel_mm_s2", 1000.0),
            max_rates={k: v for k, v in arm.items() if k in MAX_RATES},
            realtime=arm.get("realtime", False),
        )
    return made


class SimWristCamera(_Connectable, Camera):
    """A small pinhole camera on the gripper, looking along the tool axis (the published cell
    uses one to check an object's colour before sorting it)."""

    _kind = "wrist_camera"

    def __init__(
        self,
        cell: SimCell,
        width: int = 320,
        height: int = 240,
        fov_deg: float = 70.0,
        offset_mm: float = 40.0,
    ) -> None:
        super().__init__(cell)
        if cell.world.arm is None:
            raise _sim_device_error(
                "[camera].scene", f"scene {cell.scene.name!r} has no robot to carry a wrist camera"
            )
        self.width, self.height, self.fov_deg = int(width), int(height), float(fov_deg)
        self.offset_mm = float(offset_mm)
        self._sequence = 0

    @property
    def resolution(self) -> tuple[int, int]:
        return (self.width, self.height)

    @property
    def serial(self) -> str:
        return f"SIM-wrist-{self.cell.scene.name}-{self.width}x{self.height}"

    @property
    def tone_curve(self) -> str:
        """pybullet's rasteriser writes its shading as computed."""
        return "linear"

    def pose_S(self) -> np.ndarray:
        """Camera pose in S (4x4 mm): on the gripper body, looking along the tool z."""
        world = self.cell.world
        assert world.arm is not None
        T = world.link_pose(world.arm.body, world.arm.gripper_link)
        spec = self.cell.scene.robot
        assert spec is not None
        along = spec.gripper.body_length_mm
        return T @ homogeneous(np.eye(3), np.array([self.offset_mm, 0.0, along]))

    def grab(self, timeout_s: float | None = None) -> Frame:
        self._require()
        with self.cell.lock:
            world = self.cell.world
            T = self.pose_S()
            eye = T[:3, 3] * MM
            target = eye + T[:3, 2]
            view = p.computeViewMatrix(list(eye), list(target), list(-T[:3, 0]))
            proj = p.computeProjectionMatrixFOV(self.fov_deg, self.width / self.height, 0.01, 10.0)
            _, _, rgba, _, seg = p.getCameraImage(
                self.width,
                self.height,
                view,
                proj,
                renderer=p.ER_TINY_RENDERER,
                shadow=0,
                physicsClientId=world.client,
            )
        img = np.asarray(rgba, np.uint8).reshape(self.height, self.width, 4)[..., 2::-1].copy()
        # The floor is shaded analytically for the fisheye; here it is a flat colour.
        floor = np.asarray(self.cell.scene.floor.work_area_color.rgb) * 255.0
        img[np.asarray(seg).reshape(self.height, self.width) < 0] = floor[::-1].astype(np.uint8)
        self._sequence += 1
        return Frame.now(np.ascontiguousarray(img), self._sequence)
