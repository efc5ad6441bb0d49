"""Table 3 with measurement captures: the same configurations and seeds as the rendered
datasets (`sim_backend.dataset`), but each target is seen by the simulated camera in its
"real camera" mode and measured the way the cell measures: N laser-on and N laser-off frames
(uncompressed, stripe exposure), the stripe found in their difference, and N laser-off board
frames for edges and markers (`pipeline.measurement_capture`). Errors against truth as in
`evaluation.table3` (same rows, same summary), plus the capture time.

`--frames 1` without differencing is the rendered degraded dataset (`evaluate_dataset`).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.radiometry import ToneCurve
from omnisort_hw.errors import OmnisortError
from omnisort_hw.evaluation.table3 import (
    RUNS,
    TARGET_OF,
    MethodStats,
    mapping_errors,
)
from omnisort_hw.pipeline.extrinsics import calibrate_system
from omnisort_hw.pipeline.measurement_capture import (
    CaptureSettings,
    MeasurementCapture,
    capture_measurement,
)
from sim_backend.dataset import TABLE3_SCENES, table3_configs
from sim_backend.devices import SimCamera, SimCell, SimLaserSwitch
from sim_backend.scene import Scene, load_scene, sized

EVAL_GRAB_TIMEOUT_S = 900.0  # a first 1920 px render on a loaded machine takes minutes


def _measure(
    scene: Scene, seed: int, settings: CaptureSettings
) -> tuple[MeasurementCapture, dict[str, Any]]:
    cell = SimCell(scene, seed)
    try:
        with (
            SimCamera(cell, degraded=True, grab_timeout_s=EVAL_GRAB_TIMEOUT_S) as cam,
            SimLaserSwitch(cell) as laser,
        ):
            laser.on()
            cam.grab(with_truth=True)
            truth = cam.last_truth
            assert truth is not None
            return capture_measurement(cam, laser, settings), truth
    finally:
        cell.close()


def _calibrate(
    method: str, scene: str, cap: MeasurementCapture, truth: dict[str, Any], tone: ToneCurve
) -> SystemCalibration:
    model = OcamModel.from_dict(truth["camera"])
    assert cap.board_image is not None
    target = TARGET_OF[scene]
    if target == "checkerboards":
        boards = truth.get("checkerboards") or []
        return calibrate_system(
            cap.board_image,
            model,
            target,
            method,
            board=tuple(boards[0]["inner_corners"]) if boards else (9, 6),
            square_mm=float(boards[0]["square_mm"]) if boards else 97.0,
            tone=tone,
            stripe_px=cap.stripe_px,
        )
    return calibrate_system(
        cap.board_image,
        model,
        target,
        method,
        separation_mm=float(truth["target"]["separation_mm"]),
        tone=tone,
        stripe_px=cap.stripe_px,
    )


def evaluate_captures(
    n: int,
    seed: int,
    frames: int,
    width: int | None = None,
    progress: bool = True,
    partial: Path | None = None,
) -> dict[str, Any]:
    """Every configuration measured with captures of `frames` on/off pairs; the summary of
    `evaluate_dataset` plus the capture times. `partial`: a JSON file rewritten after every
    configuration (for long runs)."""
    from tqdm import tqdm

    bases = [
        (name, sized(load_scene(name), width).replace(render={"tone_curve": "srgb"}))
        for name in TABLE3_SCENES
    ]
    settings = CaptureSettings(frames=frames)
    tone = ToneCurve.srgb()  # the simulated camera's nominal curve; a capture measures its own
    stats = {m: MethodStats() for m in RUNS}
    mapping: list[np.ndarray] = []
    capture_s: list[float] = []
    retries = 0
    configs = table3_configs(n, seed)
    result: dict[str, Any] = {}
    bar = tqdm(total=n * len(bases), desc="captures", unit="target", disable=not progress)
    for done, cfg in enumerate(configs, 1):
        for k, (name, base) in enumerate(bases):
            image_seed = seed * 100003 + cfg.index * 7 + k  # as the rendered dataset
            try:
                cap, truth = _measure(cfg.apply(base), image_seed, settings)
            except (OmnisortError, Exception) as exc:  # a device error is a failure here too
                if not isinstance(exc, OmnisortError) and not hasattr(exc, "code"):
                    raise
                for row, (_, scene) in RUNS.items():
                    if scene == name:
                        stats[row].failures.append(f"{cfg.folder}/{name}: {exc}")
                bar.update(1)
                continue
            capture_s.append(float(cap.record["capture_s"]))
            retries += int(cap.record["retries"])
            for row, (method, scene) in RUNS.items():
                if scene != name:
                    continue
                t0 = time.perf_counter()
                try:
                    calib = _calibrate(method, scene, cap, truth, cap.tone or tone)
                except OmnisortError as exc:
                    stats[row].failures.append(f"{cfg.folder}: {exc}")
                    continue
                stats[row].add(calib, truth, time.perf_counter() - t0)
                if row == "joint":
                    mapping.append(mapping_errors(calib, SystemCalibration.from_json(truth)))
            bar.update(1)
        rel = np.concatenate(mapping) if mapping else np.zeros(0)
        result = {
            "n": n,
            "done": done,
            "seed": seed,
            "degraded": True,
            "frames": frames,
            "differencing": True,
            "width": width or 1920,
            "methods": {m: s.summary() for m, s in stats.items()},
            "mapping": {
                "max_rel_error": float(rel.max()) if rel.size else None,
                "mean_rel_error": float(rel.mean()) if rel.size else None,
                "samples": int(rel.size),
            },
            "capture": {
                "mean_capture_s": float(np.mean(capture_s)) if capture_s else None,
                "re_exposures": retries,
            },
        }
        if partial is not None:
            partial.parent.mkdir(parents=True, exist_ok=True)
            partial.write_text(json.dumps(result))
    bar.close()
    return result
