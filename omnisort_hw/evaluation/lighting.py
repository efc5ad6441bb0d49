"""Hostile light: every scenario of `sim_backend.hostile_light`, measured with a single frame
(the method before measurement captures: one laser-on frame as the camera is configured,
10 ms, MJPG) and with the measurement capture (laser on/off pairs, N frames, uncompressed,
exposure per task), on the sorting cell (target, cubes, bins, robot in view).

Per scenario and method:
* `laser_points`: stripe points found; `spurious_points`: those farther than 3 px from every
  true laser polyline and from every pixel the renderer lit directly (the polylines cover the
  planar faces; the robot's round base is lit too);
* `mapping_max_rel_error`: over the points within 3 px of a polyline, the largest relative
  error of the mapped horizontal range (what `omnisort map` reports) against the range of the
  nearest true polyline sample, both through the true calibration (so it measures the
  acquisition alone); the map's points farther than 3 px count as spurious instead;
* `calibration_max_error_deg` / `_mm`: the joint extrinsic calibration from the same
  acquisition against truth (largest angle error, and the laser distance error);
* `capture_s`: exposure plus laser switching time; `wall_s`: the simulator's wall time.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from omnisort_hw.core.extrinsics.system_calibration import PARAMETERS, SystemCalibration
from omnisort_hw.core.mapping import pixels_to_plane
from omnisort_hw.core.radiometry import ToneCurve
from omnisort_hw.errors import OmnisortError
from omnisort_hw.evaluation.table3 import truth_parameters
from omnisort_hw.pipeline.extrinsics import calibrate_system
from omnisort_hw.pipeline.measurement_capture import (
    CaptureSettings,
    MeasurementCapture,
    capture_measurement,
    single_frame,
)
from sim_backend.devices import SimCamera, SimCell, SimLaserSwitch
from sim_backend.hostile_light import SCENARIOS

SPURIOUS_PX = 3.0
SCENE = "sorting"


def _true_pixels(truth: dict[str, Any]) -> np.ndarray:
    parts = [np.asarray(p["points_px"], float) for p in truth["laser_polylines_px"]]
    return np.concatenate(parts) if parts else np.zeros((0, 2))


def score_points(
    pixels: np.ndarray, truth: dict[str, Any], direct_laser: np.ndarray | None
) -> dict[str, Any]:
    """Spurious points and the mapping error of stripe points against the truth."""
    poly = _true_pixels(truth)
    n = int(pixels.shape[0])
    out: dict[str, Any] = {"laser_points": n, "spurious_points": 0, "mapping_max_rel_error": None}
    if n == 0 or poly.shape[0] == 0:
        return out
    d_poly, idx = cKDTree(poly).query(pixels)
    near = d_poly <= SPURIOUS_PX
    far = ~near
    if direct_laser is not None and far.any():
        lit = np.argwhere(direct_laser > 0.05 * float(direct_laser.max()))[:, ::-1].astype(float)
        if lit.size:
            d_lit, _ = cKDTree(lit).query(pixels[far])
            far[np.flatnonzero(far)[d_lit <= SPURIOUS_PX]] = False
    out["spurious_points"] = int(far.sum())
    true_calib = SystemCalibration.from_json(truth)
    got = pixels_to_plane(pixels[near], true_calib)
    want = pixels_to_plane(poly[idx[near]], true_calib)
    r_got = np.hypot(got[:, 0], got[:, 1])
    r_want = np.hypot(want[:, 0], want[:, 1])
    ok = np.isfinite(r_got) & np.isfinite(r_want) & (r_want > 0)
    if ok.any():
        rel = np.abs(r_got[ok] - r_want[ok]) / r_want[ok]
        out["mapping_max_rel_error"] = float(rel.max())
        out["mapping_mean_rel_error"] = float(rel.mean())
    return out


def _calibration_error(
    acq: MeasurementCapture, truth: dict[str, Any], tone: ToneCurve, differenced: bool
) -> dict[str, Any]:
    model = SystemCalibration.from_json(truth).model
    sep = float(truth["target"]["separation_mm"])
    try:
        calib = calibrate_system(
            acq.board_image if acq.board_image is not None else acq.stripe_image,
            model,
            "two-sided",
            "joint",
            separation_mm=sep,
            tone=tone,
            stripe_px=acq.stripe_px if differenced else None,
        )
    except OmnisortError as exc:
        return {"calibration_error": str(exc)}
    want = truth_parameters(truth)
    got = calib.parameters()
    err = {k: got[k] - want[k] for k in PARAMETERS}
    angles = [abs(v) for k, v in err.items() if k.endswith("_deg")]
    return {
        "calibration_max_error_deg": float(max(angles)),
        "calibration_distance_error_mm": float(abs(err["laser_distance_mm"])),
    }


def run_scenario(
    name: str, seed: int, frames: int = 8, width: int = 1280, calibrate: bool = True
) -> dict[str, Any]:
    """Single frame and measurement capture under one lighting scenario."""
    cell = SimCell.from_scene(SCENE, seed=seed, light=name, width=width, height=width)
    cam = SimCamera(cell, degraded=True)
    laser = SimLaserSwitch(cell)
    tone = ToneCurve.parse(cam.tone_curve)
    result: dict[str, Any] = {"lighting": name, "seed": seed, "width": width}
    try:
        with cam, laser:
            laser.on()
            cam.grab(with_truth=True)
            truth = cam.last_truth
            assert truth is not None
            frames_src = cam._frames
            direct = frames_src.direct_laser if frames_src is not None else None
            for key, run in (
                ("single", lambda: single_frame(cam, laser)),
                ("capture", lambda: capture_measurement(cam, laser, CaptureSettings(frames))),
            ):
                try:
                    acq = run()
                except OmnisortError as exc:
                    result[key] = {"error": str(exc)}
                    continue
                except Exception as exc:
                    if not hasattr(exc, "code"):
                        raise
                    result[key] = {"error": f"{exc.code}: {exc}"}
                    continue
                entry = score_points(acq.stripe_px, truth, direct)
                entry["capture_s"] = acq.record.get("capture_s")
                entry["wall_s"] = acq.record.get("wall_s")
                entry["record"] = acq.record
                if calibrate:
                    entry.update(_calibration_error(acq, truth, tone, key == "capture"))
                result[key] = entry
    finally:
        cell.close()
    return result


def evaluate_lighting(
    seed: int,
    frames: int = 8,
    width: int = 1280,
    scenarios: tuple[str, ...] = SCENARIOS,
    progress: bool = True,
) -> dict[str, Any]:
    """Every scenario (see the module docstring); JSON-ready."""
    from tqdm import tqdm

    out: dict[str, Any] = {"seed": seed, "frames": frames, "width": width, "scenarios": {}}
    for name in tqdm(scenarios, desc="lighting", unit="scenario", disable=not progress):
        out["scenarios"][name] = run_scenario(name, seed, frames, width)
    return out


def format_lighting(result: dict[str, Any]) -> str:
    """scenario x (single, capture) x (spurious, points, mapping error, calibration, time)."""
    lines = [
        f"{'scenario':>12} | {'method':>8} | {'spurious':>8} | {'points':>6} | "
        f"{'map err %':>9} | {'cal deg':>7} | {'cal mm':>6} | {'capture s':>9}"
    ]
    for name, sc in result["scenarios"].items():
        for key in ("single", "capture"):
            e = sc.get(key, {})
            if "error" in e:
                lines.append(f"{name:>12} | {key:>8} | {e['error'][:60]}")
                continue

            def f(v: Any, fmt: str) -> str:
                return format(v, fmt) if isinstance(v, (int, float)) else "-"

            mre = e.get("mapping_max_rel_error")
            lines.append(
                f"{name:>12} | {key:>8} | {e['spurious_points']:>8} | {e['laser_points']:>6} | "
                f"{f(100 * mre if mre is not None else None, '9.3f')} | "
                f"{f(e.get('calibration_max_error_deg'), '7.4f')} | "
                f"{f(e.get('calibration_distance_error_mm'), '6.2f')} | "
                f"{f(e.get('capture_s'), '9.3f')}"
            )
    return "\n".join(lines)
