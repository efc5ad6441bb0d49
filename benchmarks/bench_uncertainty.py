"""Uncertainty end to end: the intrinsics' projection uncertainty on the real Fisheye2 photographs
beside mrcal's, the calibration of the map's and the cubes' sigmas against simulator truth on
seeds nothing was tuned on, a sort gated on the cubes' sigma, and what the sigmas cost a map.

Seeds: OMNISORT_UNCERTAINTY_SEEDS (comma-separated); the default list was not looked at while
the error model was built (that used seeds 0 to 3, and the cubes' outline correlation and the
tone curve of their calibration were found on seeds 100 to 105).
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from omnisort_hw.core.checkerboard import BoardSpec

DEFAULT_SEEDS = tuple(range(200, 212))
WIDTH = 960
# mrcal 2.2 on the same photographs (shared/reference/README.md): projection uncertainty and
# leave-one-image-out error of its best model.
MRCAL_FISHEYE2 = {
    "projection_px_centre": 0.06,
    "projection_px_45_70_deg": [0.08, 0.16],
    "projection_px_80_deg": [0.25, 0.88],
    "leave_one_out_rms_px_opencv8": 0.113,
}
FISHEYE2_BOARD = BoardSpec(8, 6, 117.0)


def seeds() -> list[int]:
    text = os.environ.get("OMNISORT_UNCERTAINTY_SEEDS", "")
    return [int(s) for s in text.split(",") if s.strip()] or list(DEFAULT_SEEDS)


def _fisheye2(shared: Path) -> dict[str, Any]:
    from omnisort_hw.pipeline.intrinsics import calibrate_intrinsics, read_images

    folder = shared / "reference" / "real" / "fisheye2"
    paths = sorted(folder.glob("Fisheye2_*.jpg"))
    if not paths:
        return {"skipped": f"no real photographs in {folder}"}
    cal = calibrate_intrinsics(read_images(paths), FISHEYE2_BOARD)
    rec = cal.record
    return {
        "images_given": len(paths),
        "images_used": len(cal.result.images_used),
        "repeated_views": [
            f"{Path(r['file']).name} = {Path(r['same_as']).name}" for r in rec["repeated_views"]
        ],
        "in_sample_rms_px": rec["cross_validation"]["in_sample_rms_px"],
        "cross_validation_rms_px": rec["cross_validation"]["rms_px"],
        "cross_validation_scheme": rec["cross_validation"]["scheme"],
        "projection_px_at_deg": rec["projection_uncertainty"]["median_px_at_angle_deg"],
        "projection_px_max_in_view": rec["projection_uncertainty"]["max_px_in_view"],
        "mrcal": MRCAL_FISHEYE2,
    }


def _split(parts: list[Any]) -> dict[str, Any]:
    from omnisort_hw.evaluation.uncertainty import Normalised, concat

    allp = concat(parts)
    out = {}
    for label, mask in (
        ("walls", np.char.startswith(allp.surfaces, "wall")),
        ("floor", np.char.startswith(allp.surfaces, "floor")),
    ):
        sub = Normalised(allp.errors[mask], allp.sigmas[mask], allp.seeds[mask])
        out[label] = sub.figures() if mask.any() else {"n": 0}
    return out


def _cost() -> dict[str, Any]:
    """One 1920 px frame of the two-sided target, one core: the map as bench_extrinsics times it
    (stripe, plane, segments), then with every point's sigma; and the whole `map_laser` (echoes,
    stripe ends) without and with sigmas, with the extrinsics' covariance and with an intrinsic
    covariance of the model's 17 parameters too."""
    from dataclasses import replace

    from omnisort_hw.core.camera_model import OcamModel
    from omnisort_hw.core.laser_stripe import laser_stripe_points_stats
    from omnisort_hw.core.map_uncertainty import point_sigmas, stripe_pixel_sigma
    from omnisort_hw.core.mapping import pixels_to_plane, segments
    from omnisort_hw.pipeline.extrinsics import calibrate_system
    from omnisort_hw.pipeline.laser_map import map_laser
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

    def plain() -> Any:
        px, _ = laser_stripe_points_stats(image)
        return segments(pixels_to_plane(px, calib), calib)

    def with_sigmas() -> Any:
        px, st = laser_stripe_points_stats(image)
        pts = pixels_to_plane(px, calib)
        point_sigmas(px, calib, stripe_pixel_sigma(px, st.chains), pts)
        return segments(pts, calib)

    rs = 0.5 * min(model.image_size)
    g = -model.poly
    vec = np.array([*model.center_uv, 1.0, 0.0, g[0], *(g[2:] * rs ** np.arange(2, len(g)))])
    unc = {
        "parameters": vec.tolist(),
        "covariance": np.diag((1e-4 * np.abs(vec) + 1e-6) ** 2).tolist(),
        "rho_scale": rs,
        "poly_degree": len(g) - 1,
    }
    calib_i = replace(calib, model=replace(model, uncertainty=unc))
    calib_i.covariance = {
        **calib.covariance,
        "intrinsics_modes": np.zeros((len(vec), 6)).tolist(),
    }
    px0, st0 = laser_stripe_points_stats(image)
    pts0 = pixels_to_plane(px0, calib)

    def sigmas_only() -> Any:
        return point_sigmas(px0, calib, stripe_pixel_sigma(px0, st0.chains), pts0)

    cv2.setNumThreads(1)
    try:
        out = {
            "sigmas_only_ms_one_core": _best_ms(sigmas_only),
            "points": len(px0),
            "map_1920_ms_one_core": _best_ms(plain),
            "map_1920_with_sigmas_ms_one_core": _best_ms(with_sigmas),
            "map_laser_1920_ms_one_core": _best_ms(
                lambda: map_laser(image, calib, with_sigmas=False)
            ),
            "map_laser_1920_with_sigmas_ms_one_core": _best_ms(lambda: map_laser(image, calib)),
            "map_laser_1920_with_sigmas_and_intrinsic_modes_ms_one_core": _best_ms(
                lambda: map_laser(image, calib_i)
            ),
            "intrinsic_modes": len(vec),
        }
    finally:
        cv2.setNumThreads(-1)
    out["load_average_1min"] = round(os.getloadavg()[0], 1)
    return out


def _best_ms(fn: Any, repeat: int = 10) -> float:
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return round(min(times) * 1e3, 1)


def run(shared: Path) -> dict[str, Any]:
    from omnisort_hw.evaluation.uncertainty import concat, cube_trial, gated_sort, map_trial

    chosen = seeds()
    figures: dict[str, Any] = {"seeds": chosen, "width_px": WIDTH}
    figures["fisheye2"] = _fisheye2(shared)
    maps, cubes, failed = [], [], []
    for s in chosen:
        try:
            maps.append(map_trial(s, WIDTH))
        except Exception as exc:  # a render where the target's features are not found
            failed.append(f"map {s}: {type(exc).__name__}: {exc}"[:160])
        try:
            cubes.append(cube_trial(s, WIDTH))
        except Exception as exc:
            failed.append(f"cubes {s}: {type(exc).__name__}: {exc}"[:160])
    figures["map"] = _split(maps)
    figures["cubes"] = concat(cubes).figures() if cubes else {"n": 0}
    figures["failed_trials"] = failed
    figures["gated_sort"] = gated_sort(WIDTH)
    figures["cost"] = _cost()
    return figures
