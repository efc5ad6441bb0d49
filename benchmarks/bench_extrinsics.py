"""Camera-laser calibration: speed of one calibration and of one map, and every method on the
third-party reference images. (The Table 3 comparison is bench_table3.py.)
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.laser_stripe import laser_stripe_points
from omnisort_hw.core.mapping import pixels_to_plane, segments
from omnisort_hw.evaluation.reference_accuracy import intrinsics_model, run_reference
from omnisort_hw.pipeline.extrinsics import calibrate_system


def _best(fn: Any, repeat: int = 5) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def _speed() -> dict[str, Any]:
    from sim_backend.scene import load_scene
    from sim_backend.scene_images import render_scene

    scene = load_scene("two_sided").replace(
        camera={"roll_deg": 4.0, "pitch_deg": -6.0, "yaw_deg": 3.0},
        laser={"roll_deg": -5.0, "pitch_deg": 7.0},
    )
    image, truth = render_scene(scene, seed=5)
    model = OcamModel.from_dict(truth["camera"])
    sep = truth["target"]["separation_mm"]
    calib = calibrate_system(image, model, "two-sided", "joint", separation_mm=sep)
    cv2.setNumThreads(1)
    t_cal = _best(lambda: calibrate_system(image, model, "two-sided", "joint", separation_mm=sep))
    t_map = _best(lambda: segments(pixels_to_plane(laser_stripe_points(image), calib), calib), 10)
    cv2.setNumThreads(-1)
    return {
        "calibration_1920_joint_s": round(t_cal, 3),
        "calibration_speedup_vs_published_28_39s": round(28.39 / t_cal, 1),
        "map_1920_frame_ms_one_core": round(t_map * 1e3, 1),
    }


def _reference(shared: Path) -> dict[str, Any]:
    ref = shared / "reference" / "unity"
    if not sorted((ref / "intrinsics").glob("a*.jpg")):
        return {"reference": f"skipped: no reference images under {ref}"}
    runs = run_reference(ref, intrinsics_model(ref))
    params = {row: r.parameters for row, r in runs.items()}
    out: dict[str, Any] = {
        f"reference_{row}": {k: round(v, 3) for k, v in p.items()} for row, p in params.items()
    }
    keys = [k for k in next(iter(params.values())) if k.endswith("_deg")]
    spread = {k: round(float(np.ptp([p[k] for p in params.values()])), 3) for k in keys}
    out["reference_max_disagreement_deg"] = spread
    out["reference_floor_lines"] = {row: r.floor_lines for row, r in runs.items() if r.floor_lines}
    return out


def _reference_accuracy(shared: Path) -> dict[str, Any]:
    """Signed errors against the exact scene (its angles, the rendered stripe's 953.5 mm), the
    wall targets as the scene's target description gives them, with the camera's tone curve
    modelled (sRGB, `after`) and ignored (values taken as light: `before`); `symmetric`: sRGB
    with the symmetric paper target assumed instead of the description. And the extracted
    borders and stripes against the scene through its own camera (the renderer's effects)."""
    from omnisort_hw.core.radiometry import SRGB, ToneCurve
    from omnisort_hw.evaluation.reference_accuracy import (
        RUNS,
        intrinsics_model,
        intrinsics_spread,
        run_reference,
        scene_check,
        summary,
    )
    from omnisort_hw.evaluation.reference_scene import feature_offsets

    ref = shared / "reference" / "unity"
    if not (ref / "intrinsics").is_dir():
        return {"reference_errors": f"skipped: no reference images under {ref}"}
    model = intrinsics_model(ref)
    return {
        "reference_errors_before": summary(run_reference(ref, model, ToneCurve.identity())),
        "reference_errors_after": summary(run_reference(ref, model, SRGB)),
        "reference_errors_symmetric_target": summary(
            run_reference(ref, model, SRGB, described=False)
        ),
        "reference_features_vs_scene": feature_offsets(
            ref, {name: kind for _, name, kind in RUNS.values() if kind != "checkerboards"}
        ),
        "reference_intrinsics_jackknife_half_range": intrinsics_spread(ref, SRGB),
        "reference_scene_with_authors_settings": scene_check(ref, model, SRGB),
    }


def run(shared: Path) -> dict[str, Any]:
    figures = _speed()
    figures.update(_reference(shared))
    figures.update(_reference_accuracy(shared))
    return figures
