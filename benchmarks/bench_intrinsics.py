"""Intrinsic calibration on the third-party renders and on real photographs, against OpenCV's
fisheye model and the Python port of OCamCalib, the camera model's mapping speed, and the
corner refinements (saddle point, on the board plane, chosen per image) side by side.

RMS figures are the RMS of the 2D reprojection distance (what this project reports, and what
OpenCV 5's fisheye.calibrate returns); per coordinate it is 2D / sqrt 2.
"""

from __future__ import annotations

import os
import resource
import tempfile
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.checkerboard import BoardSpec
from omnisort_hw.core.intrinsics import calibrate_images

UNITY_BOARD = BoardSpec(9, 6, 116.0)
FISHEYE2_BOARD = BoardSpec(8, 6, 117.0)
# py-OCamCalib (its own detector and refinement) on the same images, as measured for the
# issue: images used, 2D RMS (it prints the mean distance: 0.087 and 0.259 px), time.
PEER = {
    "fisheye2": {"images_used": 16, "of": 16, "rms_px_2d": 0.105, "time_s": 40},
    "second_lens_1032x778": {"images_used": 12, "of": 15, "rms_px_2d": 0.306, "time_s": 110},
}
OPENCV_FOCAL_UNITY_PX = 610.7  # cv2.fisheye focal on the Unity set (K[0, 0])


def _opencv_fisheye(images: list[np.ndarray], board: BoardSpec) -> dict[str, Any]:
    """OpenCV's own pipeline: full-resolution detection (classic, then the sector-based
    detector), 11x11 cornerSubPix, cv2.fisheye.calibrate from an equidistant guess."""
    t0 = time.perf_counter()
    corners = []
    for img in images:
        gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        ok, pts = cv2.findChessboardCorners(
            gray, board.size, cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        )
        if ok:
            pts = cv2.cornerSubPix(
                gray,
                pts,
                (11, 11),
                (-1, -1),
                (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3),
            )
        else:
            ok, pts = cv2.findChessboardCornersSB(gray, board.size, cv2.CALIB_CB_ACCURACY)
        if ok:
            corners.append(pts.reshape(1, -1, 2).astype(np.float64))
    t_detect = time.perf_counter() - t0
    h, w = images[0].shape[:2]
    obj = [board.object_points().reshape(1, -1, 3)] * len(corners)
    f0 = min(w, h) / np.pi  # equidistant, 180 deg across the short side
    K = np.array([[f0, 0, (w - 1) / 2], [0, f0, (h - 1) / 2], [0, 0, 1]])
    D = np.zeros((1, 4))
    flags = cv2.CALIB_RECOMPUTE_EXTRINSIC | cv2.CALIB_FIX_SKEW | cv2.CALIB_USE_INTRINSIC_GUESS
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    t1 = time.perf_counter()
    try:
        _, K, D, rvecs, tvecs = cv2.fisheye.calibrate(
            obj, corners, (w, h), K, D, flags=flags, criteria=crit
        )
    except cv2.error as exc:
        return {
            "opencv_images_found": len(corners),
            "opencv_fisheye": f"failed: {str(exc).strip().splitlines()[-1][:120]}",
        }
    t_cal = time.perf_counter() - t1
    err = np.concatenate(
        [
            (cv2.fisheye.projectPoints(o, r, t, K, D)[0] - c).reshape(-1, 2)
            for o, c, r, t in zip(obj, corners, rvecs, tvecs, strict=True)
        ]
    )
    rms2d = float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    return {
        "opencv_images_found": len(corners),
        "opencv_detect_s": round(t_detect, 2),
        "opencv_calibrate_s": round(t_cal, 2),
        "opencv_fisheye_rms_px_2d": round(rms2d, 4),
        "opencv_fisheye_rms_px_per_coord": round(rms2d / np.sqrt(2), 4),
        "opencv_focal_px": round(float(K[0, 0]), 2),
    }


def _mapping_speed() -> dict[str, Any]:
    model = OcamModel.equidistant(1920, 1920, 185.0)
    uv = np.random.default_rng(0).uniform(-0.5, 1919.5, size=(1_000_000, 2))
    rays = model.pixel_to_ray(uv)
    t_p2r = min(_timed(lambda: model.pixel_to_ray(uv)) for _ in range(7))
    t_r2p = min(_timed(lambda: model.ray_to_pixel(rays)) for _ in range(7))
    return {
        "pixel_to_ray_1M_ms": round(t_p2r * 1e3, 1),
        "ray_to_pixel_1M_ms": round(t_r2p * 1e3, 1),
        "round_trip_max_error_px": float(np.max(np.abs(model.ray_to_pixel(rays) - uv))),
    }


def _cpu_s() -> float:
    """CPU time of this process, user and system, all threads."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _timed(fn: Any) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _ours(paths: list[Path], board: BoardSpec, repeats: int = 3) -> tuple[dict[str, Any], Any]:
    """Whole calibration (reading, detection, both fits), best of `repeats`; with the RMS
    over every corner that passed detection (nothing dropped by the residual test) too."""
    runs, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), _cpu_s()
        images = [(p.name, cv2.imread(str(p))) for p in paths]
        result = calibrate_images(images, board)
        runs.append(time.perf_counter() - t0)
        cpu.append(_cpu_s() - c0)
    untrimmed = calibrate_images(images, board, max_rounds=0)
    figures = {
        "images_used": len(result.images_used),
        "images_given": len(paths),
        "rms_px_2d": round(result.rms_px, 4),
        "rms_px_2d_no_corner_dropped": round(untrimmed.rms_px, 4),
        "corners_used": int(sum(len(v) for v in result.corners_px.values())),
        "corners_rejected": len(result.corners_rejected),
        "calibration_s": round(min(runs), 2),
        # CPU seconds of the same runs, and the machine's load: on a shared machine the wall
        # time says more about the neighbours than about the calibration.
        "calibration_cpu_s": round(min(cpu), 2),
        "load_average_1min": round(os.getloadavg()[0], 1),
        "poly_degree": result.degree,
        "focal_px": round(float(-result.model.poly[0]), 2),
        "center_uv": [round(c, 2) for c in result.model.center_uv],
        "center_std_px": [round(s, 3) for s in result.std["center_uv"]],
        "refinement_chosen": {
            m: sum(v == m for v in result.refinement.values()) for m in ("saddle", "plane")
        },
    }
    return figures, images


def _refinements(images: list[tuple[str, np.ndarray]], board: BoardSpec) -> dict[str, Any]:
    """RMS and images used with each corner refinement forced, and chosen per image."""
    out = {}
    for how in ("saddle", "plane", "auto"):
        r = calibrate_images(images, board, refinement=how)
        out[how] = {"images_used": len(r.images_used), "rms_px_2d": round(r.rms_px, 4)}
    return out


def _renders(seed: int = 3, n: int = 8) -> dict[str, Any]:
    """Corner error against the renderer's truth, per refinement, on clean and degraded
    (blur, noise, vignetting) renders: where the plane re-measurement helps, and where not."""
    import json

    from sim_backend.dataset import checkerboard_views

    out: dict[str, Any] = {}
    for degraded in (False, True):
        with tempfile.TemporaryDirectory() as tmp:
            paths = checkerboard_views(
                tmp, n=n, seed=seed, width=960, degraded=degraded, progress=False
            )
            truth = {
                p.name: np.asarray(
                    json.loads(p.with_name(p.stem + ".truth.json").read_text())["checkerboards"][0][
                        "corners_px"
                    ]
                )
                for p in paths
            }
            images = [(p.name, cv2.imread(str(p))) for p in paths]
            row = {}
            for how in ("saddle", "plane", "auto"):
                r = calibrate_images(images, UNITY_BOARD, refinement=how)
                err = np.concatenate(
                    [
                        r.corners_px[n_]
                        - _truth_in_order(truth[n_], r.corners_px[n_])[r.corner_ids[n_]]
                        for n_ in r.images_used
                    ]
                )
                row[how] = {
                    "images_used": len(r.images_used),
                    "rms_px_2d": round(r.rms_px, 4),
                    "corner_error_vs_truth_rms_px": round(
                        float(np.sqrt(np.mean(np.sum(err**2, axis=1)))), 4
                    ),
                }
            out["degraded" if degraded else "clean"] = row
    return out


def _truth_in_order(truth: np.ndarray, found: np.ndarray) -> np.ndarray:
    """The truth's corners in the detector's order (it may list the board reversed)."""
    rev = truth[::-1]
    d_fwd = np.linalg.norm(truth[: len(found)] - found, axis=1).mean()
    d_rev = np.linalg.norm(rev[: len(found)] - found, axis=1).mean()
    return truth if d_fwd <= d_rev else rev


def run(shared: Path) -> dict[str, Any]:
    figures: dict[str, Any] = _mapping_speed()
    figures["peer_py_ocamcalib"] = PEER
    folder = shared / "reference" / "unity" / "intrinsics"
    paths = sorted(folder.glob("a*.jpg"))
    if paths:
        unity, images = _ours(paths, UNITY_BOARD)
        unity.update(_opencv_fisheye([img for _, img in images], UNITY_BOARD))
        unity["focal_minus_opencv_px"] = round(unity["focal_px"] - OPENCV_FOCAL_UNITY_PX, 2)
        figures["unity"] = unity
    else:
        figures["unity"] = f"skipped: no reference images in {folder}"
    folder = shared / "reference" / "real" / "fisheye2"
    paths = sorted(folder.glob("Fisheye2_*.jpg"))
    if paths:
        real, images = _ours(paths, FISHEYE2_BOARD)
        real.update(_opencv_fisheye([img for _, img in images], FISHEYE2_BOARD))
        real["refinements"] = _refinements(images, FISHEYE2_BOARD)
        figures["fisheye2"] = real
    else:
        figures["fisheye2"] = f"skipped: no real photographs in {folder}"
    figures["renders_refinements"] = _renders()
    return figures
