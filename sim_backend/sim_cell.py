"""The simulated cell every sim device of one configuration shares (`SimCell`: one pybullet
world, its scene and truth) and the devices' shared life cycle (`_Connectable`)."""

from __future__ import annotations

import threading
import weakref
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from drivers.errors import (
    DeviceConfigError,
    DeviceDisconnectedError,
)
from omnisort_hw.core.frames import camera_rotation
from sim_backend.hostile_light import Lighting, apply_to_scene, lighting
from sim_backend.scene import Scene, load_scene, sized
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
