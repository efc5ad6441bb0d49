"""The simulated cell every sim device of one configuration shares (`SimCell`: one pybullet
world, its scene and truth) and the devices' shared life cycle (`_Connectable`)."""

from __future__ import annotations

import threading
import weakref
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p
from scipy.spatial.transform import Rotation

from drivers.errors import (
    DeviceConfigError,
    DeviceDisconnectedError,
)
from omnisort_hw.core.frames import camera_rotation, laser_normal, rot_z
from omnisort_hw.errors import ConfigError
from sim_backend.hostile_light import Lighting, apply_to_scene, lighting
from sim_backend.scene import (
    NAMED_COLORS,
    Color,
    CubeSpec,
    Scene,
    TargetSpec,
    load_scene,
    sized,
)
from sim_backend.scene_images import camera_model_for, render_world
from sim_backend.world import SimWorld


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

    def mount_camera(self, roll_deg: float, pitch_deg: float, yaw_deg: float) -> np.ndarray:
        """Mount the camera at these angles (docs/frames.md's roll, pitch, yaw of S), as the
        simulator's panel sets it; returns the new R_SC. Renders and truth follow."""
        angles = np.array([roll_deg, pitch_deg, yaw_deg], float)
        if not np.all(np.isfinite(angles)) or np.any(np.abs(angles) > 180.0):
            raise ValueError(f"camera mounting: angles must be within +-180 deg, got {angles}")
        with self.lock:
            self.world.R_SC = camera_rotation(*np.radians(angles))
            return self.world.R_SC.copy()

    def set_laser_plane(
        self, roll_deg: float | None, pitch_deg: float | None, distance_mm: float | None
    ) -> np.ndarray:
        """Turn and move the laser's emitter (docs/frames.md's angles; None keeps one as it
        is), as the simulator's panel sets it; returns the new plane (n, d). Renders and truth
        follow."""
        with self.lock:
            world = self.world
            roll = world.laser_angles_deg[0] if roll_deg is None else float(roll_deg)
            pitch = world.laser_angles_deg[1] if pitch_deg is None else float(pitch_deg)
            d = world.laser_distance if distance_mm is None else float(distance_mm)
            if not all(np.isfinite([roll, pitch, d])) or abs(roll) > 60 or abs(pitch) > 60:
                raise ValueError(
                    f"laser: roll and pitch must be within +-60 deg, got {roll}, {pitch}"
                )
            if not 50.0 <= d <= 3000.0:
                raise ValueError(f"laser: distance_mm must be within [50, 3000], got {d}")
            world.laser_angles_deg = (roll, pitch)
            world.laser_normal = laser_normal(*np.radians([roll, pitch]))
            world.laser_distance = d
            return np.array([*world.laser_normal, d])

    def set_target(
        self,
        on: bool,
        kind: str | None = None,
        center_mm: tuple[float, float] | None = None,
        yaw_deg: float | None = None,
    ) -> TargetSpec | None:
        """Put the calibration target in the cell (`on`: of `kind`, centred at `center_mm` of
        S on the floor, turned by `yaw_deg`; each None keeps the target's own) or take it away,
        as the simulator's panel does; the target as it stands now. Renders and truth follow;
        a target on a cube or a bin, or of an unknown kind, is refused (ValueError)."""
        with self.lock:
            world = self.world
            if not on:
                world.set_target(None)
                return None
            last = world.target_spec or self.scene.target or TargetSpec("two_sided")
            changes: dict[str, Any] = {
                k: v
                for k, v in (
                    ("kind", kind),
                    ("center_mm", list(center_mm) if center_mm is not None else None),
                    ("yaw_deg", yaw_deg),
                )
                if v is not None
            }
            try:  # the scene's checks: a known kind, clear of the cubes and the bins
                scene = self.scene.replace(target=last).replace(target=changes)
            except ConfigError as exc:
                raise ValueError(f"target: {exc}") from None
            world.set_target(scene.target)
            return scene.target

    def _cube_spot(self, x_mm: float, y_mm: float, size_mm: float, skip: int | None) -> None:
        """Refuse a spot off the floor's work area or on another cube."""
        x0, x1, y0, y1 = self.scene.floor.work_area_mm
        if not (np.isfinite([x_mm, y_mm]).all() and x0 <= x_mm <= x1 and y0 <= y_mm <= y1):
            raise ValueError(
                f"cube: x_mm, y_mm must be on the work area [{x0:g}, {x1:g}] x [{y0:g}, {y1:g}]"
                f" mm, got ({x_mm:g}, {y_mm:g})"
            )
        for i, (spec, body) in enumerate(self.world.info.cubes):
            centre = self.world.body_pose(body)[:3, 3]
            clear = (spec.size_mm + size_mm) / np.sqrt(2.0)  # any yaw of both
            if i != skip and np.hypot(centre[0] - x_mm, centre[1] - y_mm) < clear:
                raise ValueError(f"cube: ({x_mm:g}, {y_mm:g}) is on cube {i} ({spec.color.name})")

    def place_cube(self, index: object, x_mm: float, y_mm: float, yaw_deg: float) -> None:
        """Put cube `index` down at (x, y) of S on what is there (the floor, or the floor
        board), turned by `yaw_deg`."""
        with self.lock:
            i, spec, body = self._cube(index)
            self._cube_spot(x_mm, y_mm, spec.size_mm, skip=i)
            z = self.world.support_z(x_mm, y_mm, spec.size_mm, yaw_deg) + spec.size_mm / 2.0
            quat = Rotation.from_matrix(rot_z(np.radians(yaw_deg))).as_quat()
            p.resetBasePositionAndOrientation(
                body, [x_mm * 1e-3, y_mm * 1e-3, z * 1e-3], quat, physicsClientId=self.world.client
            )
            p.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0], physicsClientId=self.world.client)
            self.world.version += 1

    def add_cube(self, color: str, x_mm: float, y_mm: float, yaw_deg: float) -> int:
        """A new cube of a named colour (the size and mass of the scene's first cube, or a
        100 mm cube) on the floor at (x, y) of S; its index."""
        if color not in NAMED_COLORS:
            raise ValueError(f"cube: unknown colour {color!r} (known: {sorted(NAMED_COLORS)})")
        like = (
            self.scene.cubes[0]
            if self.scene.cubes
            else CubeSpec(Color("red", (1, 0, 0)), 100.0, (0, 0))
        )
        spec = CubeSpec(
            Color(color, NAMED_COLORS[color]), like.size_mm, (x_mm, y_mm), yaw_deg, like.mass_kg
        )
        with self.lock:
            self._cube_spot(x_mm, y_mm, spec.size_mm, skip=None)
            return self.world.add_cube(spec)

    def remove_cube(self, index: object, held: int | None = None) -> None:
        """Take cube `index` away (not the one the gripper holds, `held`)."""
        with self.lock:
            i, _, body = self._cube(index)
            if body == held:
                raise ValueError(f"cube: cube {i} is in the gripper; open it first")
            self.world.remove_cube(i)

    def _cube(self, index: object) -> tuple[int, CubeSpec, int]:
        """(index, spec, body) of cube `index`; ValueError when there is no such cube."""
        cubes = self.world.info.cubes
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(cubes):
            raise ValueError(f"cube: index must be 0..{len(cubes) - 1}, got {index!r}")
        return (index, *cubes[index])

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


def _sim_device_error(key: str, message: str) -> DeviceConfigError:
    return DeviceConfigError(f"{key}: {message}", key=key)
