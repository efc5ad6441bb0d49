"""Datasets rendered by the simulator: the paper's Table 3 experiment and the calibration screen.

`make_dataset(out, "table3", n, seed)`: n configurations with the camera's roll, pitch, yaw
and the laser's roll, pitch drawn uniformly within +-10 degrees; each configuration folder
`config_NNN/` holds `two_sided.png`, `three_sided.png`, `checkerboards.png`, each with its
`NAME.truth.json`; `dataset.json` at the top lists the configurations.

`checkerboard_views(out, n, seed)`: the published simulator's "calibration screen": one
checkerboard (9 x 6 inner corners, 116 mm squares by default) at n poses spread over the
whole field of view, edges included, each fully visible and not too oblique, written as
`view_NN.png` + `view_NN.truth.json`.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.frames import camera_rotation
from omnisort_hw.errors import InputError
from omnisort_hw.fileio import atomic_write_json
from sim_backend.patterns import CheckerPattern
from sim_backend.scene import (
    BoardSpec,
    Scene,
    SceneInfo,
    load_scene,
    sized,
    with_camera_effects,
)
from sim_backend.scene_images import camera_model_for, render_scene, write_render

TABLE3_SCENES = ("two_sided", "three_sided", "checkerboards")
EXPERIMENTS = ("table3",)


@dataclass(frozen=True)
class Table3Config:
    """One configuration of the Table 3 experiment (degrees)."""

    index: int
    camera_roll: float
    camera_pitch: float
    camera_yaw: float
    laser_roll: float
    laser_pitch: float

    @property
    def folder(self) -> str:
        """The configuration's folder name."""
        return f"config_{self.index:03d}"

    def apply(self, scene: Scene) -> Scene:
        """The scene with this configuration's camera and laser angles."""
        return scene.replace(
            camera={
                "roll_deg": self.camera_roll,
                "pitch_deg": self.camera_pitch,
                "yaw_deg": self.camera_yaw,
            },
            laser={"roll_deg": self.laser_roll, "pitch_deg": self.laser_pitch},
        )


def table3_configs(n: int, seed: int, max_angle_deg: float = 10.0) -> list[Table3Config]:
    """n configurations with every angle uniform in [-max, max] (seeded)."""
    rng = np.random.default_rng(seed)
    angles = rng.uniform(-max_angle_deg, max_angle_deg, (n, 5))
    return [Table3Config(i, *(round(float(a), 6) for a in row)) for i, row in enumerate(angles)]


def table3_bases(
    width: int | None = None,
    tone_curve: str = "srgb",
    scenes: Sequence[str | Path] = TABLE3_SCENES,
    effects: bool = False,
    degrade: Mapping[str, object] | None = None,
) -> list[tuple[str, Scene]]:
    """(name, scene) of each target scene of the experiment, at `width`, with the simulated
    camera's tone curve; `effects`: through the colour camera's effects
    (`scene.with_camera_effects`); `degrade`: [degrade] keys over the scene's (an effect's
    range set to zero leaves it out)."""
    bases = []
    for s in scenes:
        scene = sized(load_scene(s), width).replace(render={"tone_curve": tone_curve})
        scene = with_camera_effects(scene) if effects else scene
        bases.append(
            (Path(str(s)).stem, scene.replace(degrade=dict(degrade)) if degrade else scene)
        )
    return bases


def render_config(
    folder: Path,
    cfg: Table3Config,
    bases: Sequence[tuple[str, Scene]],
    seed: int,
    degraded: bool,
    rendered: Callable[[], None] | None = None,
) -> None:
    """Render one configuration's images into `folder` (`NAME.png`, `NAME.truth.json`); the
    noise seed of each image depends on (seed, configuration, scene) only."""
    for k, (name, base) in enumerate(bases):
        image_seed = seed * 100003 + cfg.index * 7 + k
        image, truth = render_scene(cfg.apply(base), seed=image_seed, degraded=degraded)
        write_render(folder, name, image, truth)
        if rendered is not None:
            rendered()


def dataset_index(folder: Path) -> dict[str, Any] | None:
    """The folder's `dataset.json`, or None when it has none; InputError when unreadable."""
    index = folder / "dataset.json"
    if not index.is_file():
        return None
    try:
        info = json.loads(index.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"{index}: not a readable dataset index ({exc})") from None
    if not isinstance(info, dict):
        raise InputError(f"{index}: not a dataset index (top level is not an object)")
    return info


def parameter_differences(have: Mapping[str, object], wanted: Mapping[str, object]) -> list[str]:
    """`KEY HAVE (asked WANTED)` for each parameter of `wanted` the dataset `have` records
    with another value (an index older than a parameter, `width`, is not compared on it)."""
    return [
        f"{key} {have[key]!r} (asked {value!r})"
        for key, value in wanted.items()
        if key in have and have[key] != value
    ]


def dataset_problem(out: Path, wanted: Mapping[str, object]) -> str | None:
    """Why rendering the dataset `wanted` into `out` would destroy something: a dataset of
    other parameters (each named), or files that are no dataset. None: a new or empty folder,
    or the same dataset (rendered again, the same images)."""
    if out.exists() and not out.is_dir():
        return f"{out} is a file, not a dataset folder"
    info = dataset_index(out)
    if info is not None:
        differences = parameter_differences(info, wanted)
        if differences:
            return (
                f"{out} holds another dataset ({', '.join(differences)}); it is not overwritten: "
                "give another folder, or the dataset's own parameters"
            )
        return None
    if out.is_dir() and any(out.iterdir()):
        return f"{out} is not empty and holds no dataset.json; give a new or empty folder"
    return None


def make_dataset(
    out_dir: str | Path,
    experiment: str = "table3",
    n: int = 35,
    seed: int = 0,
    width: int | None = None,
    degraded: bool = False,
    scenes: Sequence[str | Path] = TABLE3_SCENES,
    progress: bool = True,
    tone_curve: str = "srgb",
    effects: bool = False,
    degrade: Mapping[str, object] | None = None,
) -> Path:
    """Render an experiment into `out_dir`; returns the path of `dataset.json`. `tone_curve`:
    the simulated camera's ("srgb" as real cameras, or "linear"), recorded in the index;
    `effects`: through the colour camera's effects (crosstalk, chromatic aberration, bloom,
    Bayer demosaicing), which implies `degraded`, recorded too; `degrade`: [degrade] keys over
    the scenes' (e.g. one effect's range set to zero), recorded."""
    if experiment not in EXPERIMENTS:
        raise InputError(f"unknown experiment {experiment!r} (known: {', '.join(EXPERIMENTS)})")
    if n < 1:
        raise InputError(f"--n must be at least 1, got {n}")
    out = Path(out_dir)
    bases = table3_bases(width, tone_curve, scenes, effects, degrade)
    degraded = degraded or effects or bool(degrade and degrade.get("enabled"))
    params = {
        "experiment": experiment,
        "n": n,
        "seed": seed,
        "width": bases[0][1].camera.width,
        "degraded": degraded,
        "effects": effects,
        "tone_curve": tone_curve,
    }
    if degrade:
        params["degrade"] = {k: list(v) if isinstance(v, tuple) else v for k, v in degrade.items()}
    problem = dataset_problem(out, params)
    if problem:
        raise InputError(problem)
    configs = table3_configs(n, seed)
    index: dict[str, Any] = {
        **params,
        "scenes": [name for name, _ in bases],
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "configs": [],
    }
    bar = tqdm(
        total=n * len(bases),
        desc=f"sim {experiment}",
        unit="img",
        file=sys.stderr,
        disable=None if progress else True,
    )
    for cfg in configs:
        render_config(out / cfg.folder, cfg, bases, seed, degraded, lambda: bar.update(1))
        index["configs"].append(
            {
                "folder": cfg.folder,
                "camera_rotation": {
                    "roll_deg": cfg.camera_roll,
                    "pitch_deg": cfg.camera_pitch,
                    "yaw_deg": cfg.camera_yaw,
                },
                "laser_plane": {"roll_deg": cfg.laser_roll, "pitch_deg": cfg.laser_pitch},
            }
        )
    bar.close()
    return atomic_write_json(out / "dataset.json", index, keep_history=False)


# ---- calibration screen --------------------------------------------------------------------


@dataclass(frozen=True)
class ViewLimits:
    """What makes a calibration view usable: inside the lens circle with a margin, not too
    oblique, squares large enough to detect (at 1920 px; scaled with the image)."""

    circle_margin_deg: float = 2.5
    max_obliquity_deg: float = 62.0
    min_square_px: float = 26.0


def _board_corners(spec: BoardSpec) -> tuple[np.ndarray, np.ndarray]:
    """Inner corners (n, 3) and outer corners (4, 3) of a board spec in S."""
    pattern = CheckerPattern(
        spec.inner_corners[0], spec.inner_corners[1], spec.square_mm, spec.margin_mm
    )
    n = np.asarray(spec.normal, float)
    r = np.asarray(spec.right, float)
    down = np.cross(r, n)
    w, h = pattern.size
    origin = np.asarray(spec.center_mm) - r * w / 2.0 - down * h / 2.0
    ab = pattern.inner_corners_ab()
    inner = origin + ab[:, :1] * r + ab[:, 1:] * down
    outer = origin + np.array([[0, 0], [w, 0], [w, h], [0, h]])[:, :1] * r
    outer = outer + np.array([[0, 0], [w, 0], [w, h], [0, h]])[:, 1:] * down
    return inner, outer


def _view_ok(
    spec: BoardSpec,
    model: OcamModel,
    R_SC: np.ndarray,
    theta_circle: float,
    floor_z: float,
    limits: ViewLimits,
) -> bool:
    inner, outer = _board_corners(spec)
    if np.any(outer[:, 2] < floor_z + 5.0):
        return False
    pts_c = np.vstack([inner, outer]) @ R_SC
    theta = model.angle_from_axis(pts_c)
    if np.any(theta > theta_circle - np.deg2rad(limits.circle_margin_deg)):
        return False
    n = np.asarray(spec.normal, float)
    view = -inner / np.linalg.norm(inner, axis=1, keepdims=True)
    if np.any(view @ n < np.cos(np.deg2rad(limits.max_obliquity_deg))):
        return False
    px = model.ray_to_pixel(inner @ R_SC).reshape(spec.inner_corners[1], spec.inner_corners[0], 2)
    step = min(
        np.linalg.norm(np.diff(px, axis=1), axis=2).min(),
        np.linalg.norm(np.diff(px, axis=0), axis=2).min(),
    )
    return bool(step >= limits.min_square_px * model.image_size[0] / 1920.0)


def board_view_poses(
    n: int,
    seed: int,
    model: OcamModel,
    R_SC: np.ndarray,
    theta_circle: float,
    floor_z: float,
    inner_corners: tuple[int, int] = (9, 6),
    square_mm: float = 116.0,
    limits: ViewLimits | None = None,
) -> list[BoardSpec]:
    """n board poses covering the field of view ring by ring (centre, middle, edge), seeded.

    Each pose: direction of the board's centre (angle from the optical axis within its ring,
    any azimuth), a distance, a tilt of up to 40 degrees from facing the camera and any
    rotation in its plane; drawn again until the view is usable (`ViewLimits`).
    """
    limits = limits or ViewLimits()
    rng = np.random.default_rng(seed)
    top = np.rad2deg(theta_circle) - 12.0
    rings = [(0.0, 0.3 * top), (0.3 * top, 0.7 * top), (0.7 * top, top)]
    poses: list[BoardSpec] = []
    for i in range(n):
        lo, hi = rings[i % 3]
        for _ in range(4000):
            theta = np.deg2rad(rng.uniform(lo, hi))
            phi = rng.uniform(0.0, 2.0 * np.pi)
            dist = rng.uniform(1000.0, 1900.0)
            d_c = np.array(
                [np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]
            )
            d_s = R_SC @ d_c
            tilt_axis = np.cross(d_s, rng.normal(size=3))
            tilt_axis /= np.linalg.norm(tilt_axis)
            tilt = np.deg2rad(rng.uniform(0.0, 40.0))
            normal = -d_s * np.cos(tilt) + np.cross(tilt_axis, -d_s) * np.sin(tilt)
            normal /= np.linalg.norm(normal)
            ref = np.array([0.0, 0.0, 1.0]) if abs(normal[2]) < 0.9 else np.array([1.0, 0, 0])
            right = np.cross(ref, normal)
            right /= np.linalg.norm(right)
            psi = rng.uniform(0.0, 2.0 * np.pi)
            right = right * np.cos(psi) + np.cross(normal, right) * np.sin(psi)
            spec = BoardSpec(
                name="screen",
                center_mm=tuple(float(v) for v in d_s * dist),  # type: ignore[arg-type]
                normal=tuple(float(v) for v in normal),  # type: ignore[arg-type]
                right=tuple(float(v) for v in right),  # type: ignore[arg-type]
                inner_corners=inner_corners,
                square_mm=square_mm,
                margin_mm=0.35 * square_mm,
            )
            if _view_ok(spec, model, R_SC, theta_circle, floor_z, limits):
                poses.append(spec)
                break
        else:
            raise InputError(
                f"cannot place a {inner_corners[0]}x{inner_corners[1]} board of {square_mm} mm "
                f"squares fully in view in ring {lo:.0f}-{hi:.0f} deg; use smaller squares"
            )
    return poses


def screen_views(
    base: Scene,
    n: int,
    seed: int,
    inner_corners: tuple[int, int] = (9, 6),
    square_mm: float = 116.0,
) -> list[Scene]:
    """The calibration screen `base` with a board at each of n poses covering its camera's
    field of view (`board_view_poses`, seeded)."""
    model = camera_model_for(base)
    R_SC = camera_rotation(0.0, 0.0, 0.0)
    circle = min(np.deg2rad(base.camera.image_circle_fov_deg) / 2.0, model.theta_max)
    poses = board_view_poses(n, seed, model, R_SC, circle, base.floor_z, inner_corners, square_mm)
    return [base.replace(checkerboards=(spec,)) for spec in poses]


def calibration_screen_scene(width: int | None = None, model_file: str = "") -> Scene:
    """The scene of the calibration screen: the camera high above the floor, no target,
    no boom, laser off (like the published simulator's intrinsic views)."""
    scene = Scene(scene=SceneInfo("checkerboard_view", "Calibration screen view"))
    scene = scene.replace(
        camera={"height_mm": 3000.0, "model_file": model_file},
        laser={"on": False, "distance_mm": 800.0},
        boom={"enabled": False},
    )
    if model_file:
        model = camera_model_for(scene)
        w, h = model.image_size
        scene = scene.replace(camera={"width": w, "height": h})
    return sized(scene, width)


def checkerboard_views(
    out_dir: str | Path,
    n: int = 12,
    seed: int = 0,
    width: int | None = None,
    inner_corners: tuple[int, int] = (9, 6),
    square_mm: float = 116.0,
    model_file: str = "",
    degraded: bool = False,
    progress: bool = True,
) -> list[Path]:
    """Render n calibration views into `out_dir`; returns the image paths."""
    if n < 1:
        raise InputError(f"--n must be at least 1, got {n}")
    base = calibration_screen_scene(width, model_file)
    scenes = screen_views(base, n, seed, inner_corners, square_mm)
    paths = []
    bar = tqdm(
        scenes,
        desc="sim checkerboard views",
        unit="img",
        file=sys.stderr,
        disable=None if progress else True,
    )
    for i, scene in enumerate(bar):
        image, truth = render_scene(scene, seed=seed * 1009 + i, degraded=degraded)
        img_path, _ = write_render(out_dir, f"view_{i:02d}", image, truth)
        paths.append(img_path)
    return paths


__all__ = [
    "EXPERIMENTS",
    "TABLE3_SCENES",
    "Table3Config",
    "ViewLimits",
    "board_view_poses",
    "calibration_screen_scene",
    "checkerboard_views",
    "make_dataset",
    "render_config",
    "sized",
    "table3_bases",
    "table3_configs",
]
