"""What other code calls: render a scene (image + truth), write it, pick the camera model.

    image, truth = render_scene("two_sided", seed=3)             # uint8 BGR, dict
    image, truth = render_scene(scene, seed=3, degraded=True)    # the "real camera" mode
    paths = write_render(out_dir, "two_sided", image, truth)     # NAME.png + NAME.truth.json

`render_world` renders an existing `SimWorld` (the simulated camera uses it for every grab).
"""

from __future__ import annotations

import hashlib
import json
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal, overload

import cv2
import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.errors import ConfigError, InputError
from omnisort_hw.fileio import atomic_write_bytes, atomic_write_json
from sim_backend.degrade import DegradeParams, compose, degrade, encode, to_bgr8
from sim_backend.render import RenderResult, render_frame
from sim_backend.scene import Scene, load_scene
from sim_backend.truth import build_truth
from sim_backend.world import SimWorld


@lru_cache(maxsize=8)
def _equidistant(width: int, height: int, fov_deg: float) -> OcamModel:
    return OcamModel.equidistant(width, height, fov_deg)


def camera_model_for(scene: Scene) -> OcamModel:
    """The scene's camera model: its `model_file` (camera.json) or the ideal equidistant one."""
    cam = scene.camera
    if not cam.model_file:
        return _equidistant(cam.width, cam.height, cam.fov_deg)
    path = Path(cam.model_file)
    if not path.is_absolute():
        path = Path(scene.base_dir) / path
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"camera.model_file: {path} not found") from None
    except json.JSONDecodeError as exc:
        raise ConfigError(f"camera.model_file: {path} is not JSON ({exc})") from None
    try:
        model = OcamModel.from_dict(data.get("camera", data), source=str(path))
    except InputError as exc:
        raise ConfigError(f"camera.model_file: {exc}") from None
    if model.image_size != (cam.width, cam.height):
        raise ConfigError(
            f"camera.width/height: {cam.width}x{cam.height} differ from the model file's "
            f"{model.image_size[0]}x{model.image_size[1]}"
        )
    return model


def _as_scene(scene: Scene | str | Path) -> Scene:
    return scene if isinstance(scene, Scene) else load_scene(scene)


def finish_image(
    world: SimWorld,
    result: RenderResult,
    seed: int,
    degraded: bool,
    brightness: float = 1.0,
) -> tuple[np.ndarray, dict[str, Any] | None]:
    """Composite (and optionally degrade) a rendered frame; returns BGR uint8 and the settings.

    `brightness` scales the light reaching the sensor (the sim camera's exposure x gain).
    """
    spec = world.scene.laser
    base, laser = result.base, result.laser
    if brightness != 1.0:
        base, laser = base * np.float32(brightness), laser * np.float32(brightness)
    tone = world.scene.render.tone_curve
    if not degraded:
        return to_bgr8(encode(compose(base, laser, spec), tone)), None
    rng = np.random.default_rng(seed)
    params = DegradeParams.draw(world.scene.degrade, rng, spec.color.rgb)
    return degrade(base, laser, spec, params, rng, tone), params.to_dict()


def render_world(
    world: SimWorld,
    model: OcamModel,
    seed: int = 0,
    degraded: bool | None = None,
    laser_on: bool | None = None,
    with_truth: bool = True,
    brightness: float = 1.0,
) -> tuple[np.ndarray, dict[str, Any] | None]:
    """Render the world's current state: (BGR uint8 image, truth dict or None)."""
    on = world.laser_on if laser_on is None else laser_on
    deg = world.scene.degrade.enabled if degraded is None else degraded
    result = render_frame(world, model, laser_on=on)
    image, settings = finish_image(world, result, seed, deg, brightness)
    truth = build_truth(world, model, on, seed=seed, degraded=settings) if with_truth else None
    if truth is not None:
        truth["render"] = {
            "face_px": world.scene.render.face_px,
            "supersampling": world.scene.render.supersampling,
            "adaptive": world.scene.render.adaptive,
            "tone_curve": world.scene.render.tone_curve,
            "seconds": {k: round(v, 4) for k, v in result.stats.items() if k.endswith("_s")},
        }
    return image, truth


@overload
def render_scene(
    scene: Scene | str | Path,
    seed: int = ...,
    degraded: bool | None = ...,
    laser_on: bool | None = ...,
    with_truth: Literal[True] = ...,
) -> tuple[np.ndarray, dict[str, Any]]: ...


@overload
def render_scene(
    scene: Scene | str | Path,
    seed: int = ...,
    degraded: bool | None = ...,
    laser_on: bool | None = ...,
    *,
    with_truth: bool,
) -> tuple[np.ndarray, dict[str, Any] | None]: ...


def render_scene(
    scene: Scene | str | Path,
    seed: int = 0,
    degraded: bool | None = None,
    laser_on: bool | None = None,
    with_truth: bool = True,
) -> tuple[np.ndarray, dict[str, Any] | None]:
    """Build the scene's world, render it once and return (BGR uint8 image, truth; the truth
    is None only with `with_truth=False`)."""
    sc = _as_scene(scene)
    world = SimWorld(sc)
    try:
        return render_world(world, camera_model_for(sc), seed, degraded, laser_on, with_truth)
    finally:
        world.close()


def png_bytes(image: np.ndarray) -> bytes:
    """Deterministic PNG encoding of a BGR image."""
    ok, buf = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 3])
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()


def write_render(
    out_dir: str | Path, name: str, image: np.ndarray, truth: dict[str, Any] | None
) -> tuple[Path, Path | None]:
    """Write NAME.png and NAME.truth.json (with the image's file name and sha256) atomically."""
    out = Path(out_dir)
    data = png_bytes(image)
    img_path = atomic_write_bytes(out / f"{name}.png", data, keep_history=False)
    if truth is None:
        return img_path, None
    truth = dict(truth)
    truth["image"] = {
        "file": img_path.name,
        "sha256": hashlib.sha256(data).hexdigest(),
        "width": int(image.shape[1]),
        "height": int(image.shape[0]),
    }
    truth_path = atomic_write_json(out / f"{name}.truth.json", truth, keep_history=False)
    return img_path, truth_path
