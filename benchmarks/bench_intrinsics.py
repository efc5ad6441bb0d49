"""Intrinsic calibration on the third-party reference set, against OpenCV's fisheye model,
and the camera model's mapping speed.

RMS figures are given both as the RMS of the 2D reprojection distance (what this project
reports, and what OpenCV 5's fisheye.calibrate returns) and per coordinate (2D / sqrt 2).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.checkerboard import BoardSpec
from omnisort_hw.core.intrinsics import calibrate_images

BOARD = BoardSpec(9, 6, 116.0)


def _opencv_fisheye(images: list[np.ndarray]) -> dict[str, Any]:
    """OpenCV's own pipeline: full-resolution detection in a plain loop, 11x11 cornerSubPix,
    cv2.fisheye.calibrate started from an equidistant guess."""
    t0 = time.perf_counter()
    corners = []
    for img in images:
        gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        ok, pts = cv2.findChessboardCorners(
            gray, BOARD.size, cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        )
        if ok:
            pts = cv2.cornerSubPix(
                gray,
                pts,
                (11, 11),
                (-1, -1),
                (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3),
            )
            corners.append(pts.reshape(1, -1, 2).astype(np.float64))
    t_detect = time.perf_counter() - t0
    obj = [BOARD.object_points().reshape(1, -1, 3)] * len(corners)
    K = np.array([[611.0, 0, 959.5], [0, 611.0, 959.5], [0, 0, 1]])
    D = np.zeros((1, 4))
    flags = cv2.CALIB_RECOMPUTE_EXTRINSIC | cv2.CALIB_FIX_SKEW | cv2.CALIB_USE_INTRINSIC_GUESS
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    t1 = time.perf_counter()
    _, K, D, rvecs, tvecs = cv2.fisheye.calibrate(
        obj, corners, (1920, 1920), K, D, flags=flags, criteria=crit
    )
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


def _timed(fn: Any) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def run(shared: Path) -> dict[str, Any]:
    figures: dict[str, Any] = _mapping_speed()
    folder = shared / "reference" / "unity" / "intrinsics"
    paths = sorted(folder.glob("a*.jpg"))
    if not paths:
        figures["reference"] = f"skipped: no reference images in {folder}"
        return figures
    runs = []
    for _ in range(3):
        t0 = time.perf_counter()
        images = [(p.name, cv2.imread(str(p))) for p in paths]
        result = calibrate_images(images, BOARD)
        runs.append(time.perf_counter() - t0)
    figures.update(
        {
            "calibration_9_images_s": round(min(runs), 2),
            "calibration_images_used": len(result.images_used),
            "rms_px_2d": round(result.rms_px, 4),
            "rms_px_per_coord": round(result.rms_px / np.sqrt(2), 4),
            "poly_degree": result.degree,
            "center_uv": [round(c, 2) for c in result.model.center_uv],
            "center_std_px": [round(s, 3) for s in result.std["center_uv"]],
        }
    )
    figures.update(_opencv_fisheye([img for _, img in images]))
    return figures
