"""Frames of the simulated camera in its "real camera" mode: the world is rendered once per
state (arm joints and cube poses; the laser light is kept apart, so one render serves laser-on
and laser-off frames) and every grab exposes a new frame from it (`sensor.expose`: its own
noise and flicker draw, the camera's exposure, gain and pixel format)."""

from __future__ import annotations

import zlib
from typing import Any

import numpy as np
import pybullet as p

from omnisort_hw.core.camera_model import OcamModel
from sim_backend.hostile_light import Lighting, extra_light
from sim_backend.render import RenderResult, render_frame
from sim_backend.scene_images import finish_image
from sim_backend.sensor import Exposure, OpticalImage, SensorParams, expose
from sim_backend.truth import build_truth
from sim_backend.world import SimWorld


def world_state_key(world: SimWorld) -> bytes:
    """What a render depends on that can change: the camera's rotation on its mount (a knock),
    the laser plane, the target, the arm's and fingers' joints, the cubes and their poses."""
    parts = [
        np.asarray(world.R_SC, float).ravel() * 1e4,
        np.asarray(world.laser_normal, float) * 1e4,
        np.array([world.laser_distance, len(world.info.cubes)], float),
        np.array([zlib.crc32(repr(world.target_spec).encode())], float),
    ]
    if world.arm is not None:
        arm = world.arm
        moving = [*arm.joints, *arm.fingers]
        states = p.getJointStates(arm.body, moving, physicsClientId=world.client)
        parts.append(np.array([s[0] for s in states], float))
    for _, body in world.info.cubes:
        parts.append(world.body_pose(body)[:3].ravel())
    return np.round(np.concatenate(parts), 4).tobytes()


class ExposedFrames:
    """One camera's sensor on one world: fixed sensor parameters (from `seed`), a cached
    render per world state, and a fresh random draw per frame."""

    def __init__(self, world: SimWorld, model: OcamModel, seed: int, lighting: Lighting) -> None:
        self.world = world
        self.model = model
        self.seed = int(seed)
        self.lighting = lighting
        self.params = SensorParams.draw(
            world.scene.degrade, np.random.default_rng(self.seed), world.scene.laser.color.rgb
        )
        self._key: bytes | None = None
        self._optical: OpticalImage | None = None
        self.direct_laser: np.ndarray | None = None  # (H, W) the renderer's laser intensity
        self._rendered: RenderResult | None = None
        self.renders = 0

    def optical(self) -> OpticalImage:
        """The light reaching the sensor for the world's current state (rendered if new)."""
        key = world_state_key(self.world)
        if self._optical is None or key != self._key:
            scene = self.world.scene
            result = render_frame(self.world, self.model, laser_on=True)
            assert result.points_S is not None
            base, steady, extra = extra_light(
                result.base,
                result.laser,
                result.points_S,
                scene,
                self.model,
                self.world.R_SC,
                self.lighting,
            )
            rng = np.random.default_rng([self.seed, 1])  # static speckle, unevenness, ambient
            self._optical = OpticalImage.prepare(
                base, result.laser, scene.laser, self.params, rng, steady, extra
            )
            self._key = key
            self.direct_laser = result.laser
            self._rendered = result
            self.renders += 1
        return self._optical

    def clean_image(self) -> np.ndarray:
        """The renderer's own image of the current state, laser on, without the sensor: the
        bytes a clean rendered dataset holds for it (one render serves both)."""
        self.optical()
        assert self._rendered is not None
        return finish_image(self.world, self._rendered, self.seed, degraded=False)[0]

    def frame(
        self, settings: Exposure, draw: int, with_truth: bool = False
    ) -> tuple[np.ndarray, dict[str, Any] | None]:
        """One exposed frame (uint8 BGR) and, with `with_truth`, its truth dict (with the
        sensor's parameters and this frame's settings under `degraded`)."""
        rng = np.random.default_rng([self.seed, 2, int(draw)])
        image, info = expose(
            self.optical(), self.params, settings, rng, self.world.scene.render.tone_curve
        )
        if not with_truth:
            return image, None
        record = {
            **self.params.to_dict(),
            "lighting": self.lighting.name,
            "exposure_ms": settings.exposure_ms,
            "gain": settings.gain,
            "pixel_format": settings.pixel_format,
            "frame_draw": int(draw),
            **info,
        }
        truth = build_truth(
            self.world, self.model, settings.laser_on, seed=self.seed, degraded=record
        )
        return image, truth
