"""Accuracy on the authors' own renders: every method on the third-party Unity images, as
signed errors against the simulator settings the authors published for those scenes.

The settings (camera X = -3.5, Y = 1, Z = 2.5 deg; laser X = 0.5, Y = 2 deg; laser distance
950 mm; walls 1292.4 mm apart; boards of 116 mm squares) are those of the authors' MATLAB
tutorials, in system.json terms (the reference images' README says how). They measure bias; nothing
is fitted to them. Used by the extrinsics benchmark and the reference-accuracy test.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.radiometry import SRGB, ToneCurve
from omnisort_hw.pipeline.image_files import read_image

AUTHORS_SETTINGS: dict[str, float] = {
    "cam_roll_deg": 3.5,
    "cam_pitch_deg": 1.0,
    "cam_yaw_deg": -2.5,
    "laser_roll_deg": -0.5,
    "laser_pitch_deg": 2.0,
    "laser_distance_mm": 950.0,
}
SEPARATION_MM = 1292.4
SQUARE_MM = 116.0
BOARD = (9, 6)

# row -> (method, image, target)
RUNS: dict[str, tuple[str, str, str]] = {
    "joint": ("joint", "two_sided_target.png", "two-sided"),
    "paper": ("paper", "two_sided_target.png", "two-sided"),
    "method1": ("method1", "three_sided_target.png", "three-sided"),
    "joint_three_sided": ("joint", "three_sided_target.png", "three-sided"),
    "method2": ("method2", "checkerboard_b.jpg", "checkerboards"),
}


@dataclass
class ReferenceRun:
    """Parameters and signed errors (result - authors' settings) of one method on one image,
    with the standard deviations the method reports for its own result (where it does) and
    what `joint` did with the wall/floor lines (`residuals.floor_lines`; empty for the others)."""

    parameters: dict[str, float]
    errors: dict[str, float]
    std: dict[str, float] = field(default_factory=dict)
    floor_lines: str = ""


def intrinsics_model(ref_dir: Path) -> OcamModel:
    """The camera model calibrated from the authors' intrinsics views (a1..a9)."""
    from omnisort_hw.core.checkerboard import BoardSpec
    from omnisort_hw.core.intrinsics import calibrate_images

    views = sorted((ref_dir / "intrinsics").glob("a*.jpg"))
    return calibrate_images(
        [(p.name, read_image(p)) for p in views], BoardSpec(*BOARD, SQUARE_MM)
    ).model


def run_reference(
    ref_dir: Path, model: OcamModel, tone: ToneCurve = SRGB
) -> dict[str, ReferenceRun]:
    """Every method of RUNS on its image, with `tone` as the camera's tone curve."""
    from omnisort_hw.pipeline.extrinsics import calibrate_system

    images = {name: cv2.imread(str(ref_dir / name)) for _, name, _ in RUNS.values()}
    out: dict[str, ReferenceRun] = {}
    for row, (method, name, target) in RUNS.items():
        calib = calibrate_system(
            images[name],
            model,
            target,
            method,
            separation_mm=SEPARATION_MM,
            board=BOARD,
            square_mm=SQUARE_MM,
            source=name,
            tone=tone,
        )
        p = calib.parameters()
        std = {k: v for k, v in (calib.std or {}).items() if k in AUTHORS_SETTINGS}
        errors = {k: p[k] - v for k, v in AUTHORS_SETTINGS.items()}
        floor = str((calib.residuals or {}).get("floor_lines", ""))
        out[row] = ReferenceRun(p, errors, std, floor)
    return out


def cross_target(runs: dict[str, ReferenceRun]) -> dict[str, float]:
    """joint on the two-sided image minus joint on the three-sided image (same camera/laser)."""
    a, b = runs["joint"].parameters, runs["joint_three_sided"].parameters
    return {k: float(a[k] - b[k]) for k in AUTHORS_SETTINGS}


def rounded(d: dict[str, float]) -> dict[str, float]:
    return {k: round(float(v), 2 if k.endswith("_mm") else 3) for k, v in d.items()}


def summary(runs: dict[str, ReferenceRun]) -> dict[str, object]:
    """JSON-ready signed errors per method and the cross-target difference."""
    out: dict[str, object] = {row: rounded(r.errors) for row, r in runs.items()}
    out["two_minus_three_sided_joint"] = rounded(cross_target(runs))
    out["reported_std"] = {row: rounded(r.std) for row, r in runs.items() if r.std}
    return out


def worst(runs: dict[str, ReferenceRun], row: str) -> tuple[float, float]:
    """Largest |angle error| (deg) and |distance error| (mm) of one row."""
    e = runs[row].errors
    angles = [abs(v) for k, v in e.items() if k.endswith("_deg")]
    return float(np.max(angles)), abs(e["laser_distance_mm"])


def _slope_deg(along: np.ndarray, height: np.ndarray) -> float:
    """Angle (deg) of the least-squares line height = a + b * along."""
    return float(np.degrees(np.arctan(np.polyfit(along, height, 1)[0])))


def scene_check(ref_dir: Path, model: OcamModel, tone: ToneCurve = SRGB) -> dict[str, object]:
    """What the images say about the scene when the authors' camera and laser are taken as
    true. Per side wall: its inner face's X where its laser line puts it (mm, and the
    separation), its border's height and slope along the wall, and the slope of its laser
    line along the wall. With consistent settings the separation is 1292.4 mm, both borders
    stand at one height and are level, and both laser lines, and each half of each, slope as
    the authors' plane does (`laser_plane_slope_deg`: one plane meets flat parallel walls in
    parallel straight lines). On the three-sided image the far wall likewise: its Y, the
    angle of its laser line to X (0 when it is perpendicular to the side walls), and its
    border's height and slope along X."""
    from omnisort_hw.core.frames import camera_rotation, laser_normal, rays_to_plane
    from omnisort_hw.core.target_features import extract_target_features

    s = AUTHORS_SETTINGS
    R = camera_rotation(*np.radians([s["cam_roll_deg"], s["cam_pitch_deg"], s["cam_yaw_deg"]]))
    n = laser_normal(*np.radians([s["laser_roll_deg"], s["laser_pitch_deg"]]))
    offset = -s["laser_distance_mm"] * n[2]
    out: dict[str, object] = {
        "laser_plane_slope_deg": round(float(np.degrees(np.arctan(-n[1] / n[2]))), 4)
    }
    for name, kind in (
        ("two_sided_target.png", "two-sided"),
        ("three_sided_target.png", "three-sided"),
    ):
        f = extract_target_features(read_image(ref_dir / name), model, kind, tone)
        walls: dict[str, float] = {}
        heights: dict[str, float] = {}
        slopes: dict[str, float] = {}
        laser_slopes: dict[str, float] = {}
        for side in ("left", "right"):
            w = f.walls[side]
            P = rays_to_plane(model.pixel_to_ray(w.laser_px) @ R.T, n, offset)
            x = float(np.median(P[:, 0]))
            rb = model.pixel_to_ray(w.border_px) @ R.T
            B = rb * (x / rb[:, 0])[:, None]
            L = P * (x / P[:, 0])[:, None]
            walls[side] = x
            heights[side] = float(np.median(B[:, 2]))
            slopes[side] = _slope_deg(B[:, 1], B[:, 2])
            near = L[:, 1] <= np.median(L[:, 1])
            laser_slopes[side] = _slope_deg(L[:, 1], L[:, 2])
            laser_slopes[f"{side}_near_half"] = _slope_deg(L[near, 1], L[near, 2])
            laser_slopes[f"{side}_far_half"] = _slope_deg(L[~near, 1], L[~near, 2])
        entry: dict[str, object] = {
            "wall_x_mm": {k: round(v, 2) for k, v in walls.items()},
            "separation_mm": round(walls["right"] - walls["left"], 2),
            "border_z_mm": {k: round(v, 2) for k, v in heights.items()},
            "border_slope_deg": {k: round(v, 4) for k, v in slopes.items()},
            "laser_slope_deg": {k: round(v, 4) for k, v in laser_slopes.items()},
        }
        if "far" in f.walls:
            w = f.walls["far"]
            P = rays_to_plane(model.pixel_to_ray(w.laser_px) @ R.T, n, offset)
            y = float(np.median(P[:, 1]))
            rb = model.pixel_to_ray(w.border_px) @ R.T
            B = rb * (y / rb[:, 1])[:, None]
            entry["far_wall"] = {
                "y_mm": round(y, 2),
                "laser_angle_to_x_deg": round(_slope_deg(P[:, 0], P[:, 1]), 4),
                "border_z_mm": round(float(np.median(B[:, 2])), 2),
                "border_slope_deg": round(_slope_deg(B[:, 0], B[:, 2]), 4),
            }
        out[kind] = entry
    return out


def intrinsics_spread(ref_dir: Path, tone: ToneCurve = SRGB) -> dict[str, dict[str, float]]:
    """How much the intrinsic calibration alone moves each result: every method rerun with
    intrinsics from the views less one (a jackknife over a1..a9); per row and parameter the
    half range of the nine results."""
    from omnisort_hw.core.checkerboard import BoardSpec
    from omnisort_hw.core.intrinsics import calibrate_images

    views = [(p.name, read_image(p)) for p in sorted((ref_dir / "intrinsics").glob("a*.jpg"))]
    results: dict[str, list[dict[str, float]]] = {row: [] for row in RUNS}
    for k in range(len(views)):
        subset = views[:k] + views[k + 1 :]
        model = calibrate_images(subset, BoardSpec(*BOARD, SQUARE_MM)).model
        for row, run in run_reference(ref_dir, model, tone).items():
            results[row].append(run.errors)
    return {
        row: rounded({key: 0.5 * float(np.ptp([e[key] for e in errs])) for key in AUTHORS_SETTINGS})
        for row, errs in results.items()
    }
