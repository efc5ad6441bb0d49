"""Hostile light: every scenario of `sim_backend.hostile_light`, measured with a single frame
(the method before measurement captures: one laser-on frame as the camera is configured,
10 ms, MJPG) and with the measurement capture (laser on/off pairs, N frames, uncompressed,
exposure per task), on the sorting cell (target, cubes, bins, robot in view).

Per scenario and method:
* `laser_points`: the map's points (`pipeline.laser_map` through the true calibration and
  the true floor, as a registered cell knows it: the stripe found, echoes dropped);
  `spurious_points`: those farther than 3 px from every true laser polyline and from every
  pixel the renderer lit directly (the polylines cover the planar faces; the robot's round
  base is lit too);
* `mapping_max_rel_error`: what the map reports per obstacle is its nearest horizontal
  distance (`omnisort map`); per true surface with 3 or more points within 3 px, the relative
  error of the nearest mapped distance against the true one at the same places (each point's
  foot on the true polyline), both through the true calibration (the acquisition alone);
  the worst surface. `point_max_rel_error` / `point_p95_rel_error`: the same per point;
* `calibration_max_error_deg` / `_mm`: the joint extrinsic calibration from the same
  acquisition against truth (largest angle error, and the laser distance error);
* `capture_s`: exposure plus laser switching time; `wall_s`: the simulator's wall time.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from omnisort_hw.config.capture import CaptureSettings
from omnisort_hw.core.extrinsics.system_calibration import PARAMETERS, SystemCalibration
from omnisort_hw.core.mapping import pixels_to_plane
from omnisort_hw.core.radiometry import ToneCurve
from omnisort_hw.errors import OmnisortError
from omnisort_hw.evaluation.table3 import truth_parameters
from omnisort_hw.pipeline.extrinsics import calibrate_system
from omnisort_hw.pipeline.laser_map import map_laser
from omnisort_hw.pipeline.measurement_capture import (
    MeasurementCapture,
    capture_measurement,
    single_frame,
)
from omnisort_hw.sweeps.trial import Trial, TrialOutput, merge_paths, split_paths
from sim_backend.devices import SimCamera, SimCell, SimLaserSwitch
from sim_backend.hostile_light import SCENARIOS
from sim_backend.scene import load_scene, with_camera_effects

EVAL_GRAB_TIMEOUT_S = 900.0  # a first 1920 px render on a loaded machine takes minutes
SPURIOUS_PX = 3.0
SCENE = "sorting"


def nearest_on_polylines(
    points: np.ndarray, polylines: list[np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distance (px) from each point to the nearest polyline segment, the foot point on it
    (interpolated: the nearest vertex would add up to half a vertex spacing along it) and
    the index of that polyline."""
    segs = [np.stack([p[:-1], p[1:]], axis=1) for p in polylines if len(p) >= 2]
    owner_of = np.concatenate(
        [np.full(len(p) - 1, i) for i, p in enumerate(polylines) if len(p) >= 2] or [np.empty(0)]
    ).astype(int)
    pts = np.asarray(points, float).reshape(-1, 2)
    best = np.full(len(pts), np.inf)
    foot = np.full((len(pts), 2), np.nan)
    owner = np.full(len(pts), -1)
    if not segs or not len(pts):
        return best, foot, owner
    ab = np.concatenate(segs)
    a, d = ab[:, 0], ab[:, 1] - ab[:, 0]
    dd = np.maximum((d * d).sum(axis=1), 1e-12)
    for start in range(0, len(pts), 256):
        q = pts[start : start + 256, None, :]
        t = np.clip(((q - a) * d).sum(axis=2) / dd, 0.0, 1.0)
        f = a + t[..., None] * d
        dist = np.hypot(*(q - f).transpose(2, 0, 1))
        k = np.argmin(dist, axis=1)
        rows = np.arange(len(k))
        best[start : start + 256] = dist[rows, k]
        foot[start : start + 256] = f[rows, k]
        owner[start : start + 256] = owner_of[k]
    return best, foot, owner


def score_points(
    pixels: np.ndarray, truth: dict[str, Any], direct_laser: np.ndarray | None
) -> dict[str, Any]:
    """Spurious points and the mapping errors of stripe points against the truth."""
    polys = [np.asarray(p["points_px"], float) for p in truth["laser_polylines_px"]]
    surfaces = [p["surface"] for p in truth["laser_polylines_px"]]
    n = int(pixels.shape[0])
    out: dict[str, Any] = {"laser_points": n, "spurious_points": 0, "mapping_max_rel_error": None}
    if n == 0 or not polys:
        return out
    dist, foot, owner = nearest_on_polylines(pixels, polys)
    near = dist <= SPURIOUS_PX
    far = ~near
    if direct_laser is not None and far.any():
        lit = np.argwhere(direct_laser > 0.05 * float(direct_laser.max()))[:, ::-1].astype(float)
        if lit.size:
            d_lit, _ = cKDTree(lit).query(pixels[far])
            far[np.flatnonzero(far)[d_lit <= SPURIOUS_PX]] = False
    out["spurious_points"] = int(far.sum())
    true_calib = SystemCalibration.from_json(truth)
    got = pixels_to_plane(pixels[near], true_calib)
    want = pixels_to_plane(foot[near], true_calib)
    r_got = np.hypot(got[:, 0], got[:, 1])
    r_want = np.hypot(want[:, 0], want[:, 1])
    ok = np.isfinite(r_got) & np.isfinite(r_want) & (r_want > 0)
    if not ok.any():
        return out
    rel = np.abs(r_got[ok] - r_want[ok]) / r_want[ok]
    out["point_max_rel_error"] = float(rel.max())
    out["point_p95_rel_error"] = float(np.percentile(rel, 95))
    # What the map reports per obstacle: its nearest distance over the points seen on it.
    face = np.array([surfaces[i] for i in owner[near][ok]])
    worst = 0.0
    for name in np.unique(face):
        m = face == name
        if m.sum() >= 3:
            true_d = float(r_want[ok][m].min())
            worst = max(worst, abs(float(r_got[ok][m].min()) - true_d) / true_d)
    out["mapping_max_rel_error"] = worst
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
            tone=(acq.tone or tone) if differenced else tone,
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


def lighting_cell(name: str, seed: int, width: int, effects: bool = False) -> SimCell:
    """The sorting cell under the lighting scenario `name`, its camera square at `width` px;
    `effects`: through the colour camera's effects as well (crosstalk, chromatic aberration,
    bloom, Bayer demosaicing: `scene.with_camera_effects`), as a real colour camera sees."""
    scene = load_scene(SCENE)
    scene = with_camera_effects(scene) if effects else scene
    return SimCell.from_scene(scene, seed=seed, light=name, width=width, height=width)


def run_scenario(
    name: str,
    seed: int,
    frames: int = 8,
    width: int = 1280,
    calibrate: bool = True,
    effects: bool = False,
) -> dict[str, Any]:
    """Single frame and measurement capture under one lighting scenario (`effects`: through
    the colour camera's effects, `lighting_cell`)."""
    cell = lighting_cell(name, seed, width, effects)
    cam = SimCamera(cell, degraded=True, grab_timeout_s=EVAL_GRAB_TIMEOUT_S)
    laser = SimLaserSwitch(cell)
    tone = ToneCurve.parse(cam.tone_curve)
    result: dict[str, Any] = {"lighting": name, "seed": seed, "width": width}
    if effects:
        result["effects"] = True
    try:
        with cam, laser:
            laser.on()
            cam.grab(with_truth=True)
            truth = cam.last_truth
            assert truth is not None
            true_calib = SystemCalibration.from_json(truth)
            direct = cam.direct_laser
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
                floor = (np.array([0.0, 0.0, 1.0]), float(truth["target"]["floor_z_mm"]))
                lmap = map_laser(
                    acq.stripe_image, true_calib, floor_S=floor, light_only=key == "capture"
                )
                entry = score_points(lmap.pixels, truth, direct)
                entry["echoes_dropped"] = lmap.echoes
                entry["capture_s"] = acq.record.get("capture_s")
                entry["wall_s"] = acq.record.get("wall_s")
                entry["record"] = acq.record
                if calibrate:
                    entry.update(_calibration_error(acq, truth, tone, key == "capture"))
                result[key] = entry
    finally:
        cell.close()
    return result


# Entries of a scenario's result that depend on the machine: the simulator's wall times and
# the capture time, whose laser switching is measured on the wall clock.
_TIMED = ("wall_s", "capture_s", "record.wall_s", "record.capture_s", "record.laser_switching_s")
LIGHTING_TIMING = tuple(f"{key}.{path}" for key in ("single", "capture") for path in _TIMED)


def lighting_trials(
    seed: int,
    frames: int = 8,
    width: int = 1280,
    scenarios: tuple[str, ...] = SCENARIOS,
    calibrate: bool = True,
    effects: bool = False,
) -> list[Trial]:
    """One trial per scenario (the seed: the cell's noise seed, the same for every one);
    `calibrate=False` leaves out the calibrations (the map's figures alone, faster);
    `effects`: through the colour camera's effects (`lighting_cell`). A key left at its
    default is not in the configuration, so the trials run before either existed keep their
    identity."""
    config: dict[str, Any] = {"frames": frames, "width": width}
    if not calibrate:
        config["calibrate"] = False
    if effects:
        config["effects"] = True
    return [Trial("lighting", {"scenario": name, **config}, seed) for name in scenarios]


def lighting_trial(config: Mapping[str, Any], seed: int) -> TrialOutput:
    """`run_scenario` of the configuration, its wall times in timing."""
    result = run_scenario(
        config["scenario"],
        seed,
        int(config["frames"]),
        int(config["width"]),
        calibrate=bool(config.get("calibrate", True)),
        effects=bool(config.get("effects", False)),
    )
    return split_paths(result, LIGHTING_TIMING)


def summarize_lighting(
    rows: Sequence[Mapping[str, Any]], seed: int, frames: int, width: int, effects: bool = False
) -> dict[str, Any]:
    """`evaluate_lighting`'s object from a sweep's lighting rows (manifest order)."""
    scenarios = {r["config"]["scenario"]: merge_paths(r["result"], r["timing"]) for r in rows}
    out = {"seed": seed, "frames": frames, "width": width, "scenarios": scenarios}
    return {**out, "effects": True} if effects else out


def evaluate_lighting(
    seed: int,
    frames: int = 8,
    width: int = 1280,
    scenarios: tuple[str, ...] = SCENARIOS,
    progress: bool = True,
    effects: bool = False,
) -> dict[str, Any]:
    """Every scenario (see the module docstring), in this process; JSON-ready. `effects`:
    through the colour camera's effects (`lighting_cell`)."""
    from tqdm import tqdm

    out: dict[str, Any] = {"seed": seed, "frames": frames, "width": width, "scenarios": {}}
    if effects:
        out["effects"] = True
    for name in tqdm(scenarios, desc="lighting", unit="scenario", disable=not progress):
        out["scenarios"][name] = run_scenario(name, seed, frames, width, effects=effects)
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
