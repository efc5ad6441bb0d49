"""Camera-laser calibration: speed of one calibration and of one map, the Table 3 comparison
(clean and degraded), and every method on the third-party reference images.

Environment: OMNISORT_BENCH_N (configurations, default 35), OMNISORT_BENCH_SEED (default 0).
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.checkerboard import BoardSpec
from omnisort_hw.core.intrinsics import calibrate_images
from omnisort_hw.core.laser_stripe import laser_stripe_points
from omnisort_hw.core.mapping import pixels_to_plane, segments
from omnisort_hw.evaluation import evaluate_dataset
from omnisort_hw.extrinsics_pipeline import calibrate_system

BUILD = Path(__file__).resolve().parent.parent / "build" / "bench"


def _best(fn: Any, repeat: int = 5) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def _speed() -> dict[str, Any]:
    from sim_backend.api import render_scene
    from sim_backend.scene import load_scene

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


def _table3(n: int, seed: int, degraded: bool) -> dict[str, Any]:
    from sim_backend.dataset import make_dataset

    data = BUILD / (f"table3-n{n}-seed{seed}" + ("-degraded" if degraded else ""))
    if not (data / "dataset.json").is_file():
        make_dataset(data, "table3", n, seed, degraded=degraded, progress=True)
    result = evaluate_dataset(data, progress=True)
    out: dict[str, Any] = {}
    for method, s in result["methods"].items():
        if "mae" in s:
            out[f"{method}_mae"] = {k: round(v, 4) for k, v in s["mae"].items()}
            out[f"{method}_mean_time_s"] = round(s["mean_time_s"], 3)
        out[f"{method}_failures"] = len(s["failures"])
    out["mapping_max_rel_error_pct"] = (
        round(100 * result["mapping"]["max_rel_error"], 4)
        if result["mapping"]["max_rel_error"] is not None else None
    )
    return out


def _reference(shared: Path) -> dict[str, Any]:
    ref = shared / "reference" / "unity"
    views = sorted((ref / "intrinsics").glob("a*.jpg"))
    if not views:
        return {"reference": f"skipped: no reference images under {ref}"}
    model = calibrate_images([(p.name, cv2.imread(str(p))) for p in views],
                             BoardSpec(9, 6, 116.0)).model
    runs = {
        "joint": ("two_sided_target.png", "two-sided"),
        "paper": ("two_sided_target.png", "two-sided"),
        "method1": ("three_sided_target.png", "three-sided"),
        "method2": ("checkerboard_b.jpg", "checkerboards"),
    }
    params: dict[str, dict[str, float]] = {}
    out: dict[str, Any] = {}
    for method, (name, target) in runs.items():
        image = cv2.imread(str(ref / name))
        try:
            calib = calibrate_system(image, model, target, method, separation_mm=1292.4,
                                     board=(9, 6), square_mm=97.0)
        except Exception as exc:
            out[f"reference_{method}"] = f"failed: {exc}"
            continue
        params[method] = calib.parameters()
        out[f"reference_{method}"] = {k: round(v, 3) for k, v in params[method].items()}
    if len(params) > 1:
        keys = [k for k in next(iter(params.values())) if k.endswith("_deg")]
        spread = {k: round(float(np.ptp([p[k] for p in params.values()])), 3) for k in keys}
        out["reference_max_disagreement_deg"] = spread
    return out


def run(shared: Path) -> dict[str, Any]:
    n = int(os.environ.get("OMNISORT_BENCH_N", "35"))
    seed = int(os.environ.get("OMNISORT_BENCH_SEED", "0"))
    figures = _speed()
    figures.update({f"clean_{k}": v for k, v in _table3(n, seed, False).items()})
    figures.update({f"degraded_{k}": v for k, v in _table3(n, seed, True).items()})
    figures["table3_configurations"] = n
    figures.update(_reference(shared))
    return figures
