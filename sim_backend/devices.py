"""Simulated devices behind the `drivers.base` interfaces, sharing one simulated cell.

    cell = SimCell.from_scene("sorting")
    with SimCamera(cell) as cam, SimLaserSwitch(cell) as laser, SimArm(cell) as arm:
        laser.on()
        frame = cam.grab()                          # renders the world's current state
        arm.move_joints(q)                          # bounded speed, physics stepped at 240 Hz
        arm.move_linear(T_base_tcp)                 # straight line, analytic IK (core)
        arm.gripper.close()                         # grasps a cube between the fingers

`open_devices(sections, base_dir)` is the factory `omnisort_hw.cell.devices` calls for
`backend = "sim"`: every sim device of one cell configuration shares one `SimCell`.
Time in the simulator is simulated time: a move takes its planned duration of physics
steps (as fast as the computer goes, or paced to the wall clock with `realtime = true`), and
a move that would outlast its timeout is stopped there and raises `DeviceTimeoutError`.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p

from drivers.base import (
    Arm,
    Camera,
    Frame,
    LaserSwitch,
)
from drivers.errors import (
    DeviceError,
    DeviceTimeoutError,
)
from omnisort_hw.config.devices import check_sim_settings
from omnisort_hw.core.frames import homogeneous
from omnisort_hw.errors import ConfigError
from sim_backend.exposed_frames import ExposedFrames, world_state_key
from sim_backend.sensor import NOMINAL_EXPOSURE_MS, PIXEL_FORMATS, Exposure
from sim_backend.sim_arm import MAX_RATES, SimArm, SimGripper
from sim_backend.sim_cell import SimCell, _Connectable, _sim_device_error
from sim_backend.world import MM

__all__ = ["SimArm", "SimCamera", "SimCell", "SimGripper", "SimLaserSwitch", "open_devices"]

DEFAULT_SIM_GRAB_TIMEOUT_S = 60.0


CLEAN_FRAMES_KEPT = 4
"""Clean frames kept per camera: laser on and off, at two brightnesses (an exposure change)."""


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
        # The last clean frames by what they depend on (state, laser, brightness), so that a
        # measurement's alternating laser-on and laser-off grabs of one state render twice.
        self._clean: dict[Any, tuple[np.ndarray, dict | None]] = {}
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

    def clean_image(self) -> np.ndarray:
        """The renderer's clean image of the world's current state (laser on, no sensor), from
        the render the degraded frames are exposed from (degraded mode only)."""
        self._require()
        if not self.degraded:
            raise DeviceError(f"{self.name}: clean images come from the degraded mode's render")
        with self.cell.lock:
            return self._exposed().clean_image()

    def _exposed(self) -> ExposedFrames:
        if self._frames is None:
            cell = self.cell
            self._frames = ExposedFrames(cell.world, cell.model, cell.seed, cell.lighting)
        return self._frames

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
                frames = self._exposed()
                settings = Exposure(
                    self._exposure_ms,
                    self._gain,
                    bool(self.cell.world.laser_on),
                    self.cell.lighting.flicker_depth,
                    self._format,
                )
                self._draws += 1
                return frames.frame(settings, self._draws, with_truth)
        brightness = self._exposure_ms / NOMINAL_EXPOSURE_MS * self._gain
        with self.cell.lock:
            # A clean frame depends only on the state: the same state renders the same bytes.
            key = (world_state_key(self.cell.world), self.cell.world.laser_on, brightness)
            kept = self._clean.get(key)
            if kept is not None and (kept[1] or not with_truth):
                return kept
            image, truth = self.cell.render(
                self.cell.seed + sequence, self.degraded, brightness, with_truth=with_truth
            )
            self._clean.pop(key, None)  # a frame rendered again for its truth: kept anew
            if len(self._clean) >= CLEAN_FRAMES_KEPT:
                self._clean.pop(next(iter(self._clean)))  # the oldest
            image.setflags(write=False)  # one array serves every grab of this key
            self._clean[key] = (image, truth)
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


def _check_settings(kind: str, settings: dict[str, Any]) -> dict[str, Any]:
    """The section's settings checked against the schema the cell file was loaded with."""
    try:
        return check_sim_settings(kind, settings)
    except ConfigError as exc:
        key = getattr(exc, "key", f"[{kind}]")
        raise _sim_device_error(key, str(exc).removeprefix(f"{key}: ")) from None


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
    overrides: dict[str, Any] = {k: cam[k] for k in ("width", "height") if k in cam}
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
