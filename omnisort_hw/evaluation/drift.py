"""`omnisort evaluate drift`: the drift watchdog on simulated scenes with a known truth.

Per scene (the sorting scene with random camera mounting angles and cubes) and per camera
mode (clean renders, the degraded "real camera"): register the robot from a laser-off capture
with the true camera calibration, keep that capture as the reference, then
- unmoved: captures with fresh noise and the arm in random poses (some hide part of the floor
  board), every one must pass;
- bumps: the mount turned by 0.05, 0.1, 0.3 and 1 deg about X, Y and Z of S, both signs;
  each must be detected, and the implied rotation (a vector, in S) is compared with the true
  one (`max_angle_error_deg` is the largest norm of their difference).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict
from typing import Any

import numpy as np

from omnisort_hw.config.watchdog import WatchdogConfig
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.kinematics import get_model, nearest_solution
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.errors import InputError, OmnisortError
from omnisort_hw.evaluation.sorting import apply_layout, draw_layout
from omnisort_hw.pipeline.drift_check import check_drift
from omnisort_hw.pipeline.registration import register_from_image, robot_base_record
from omnisort_hw.sweeps.trial import Trial, TrialOutput, canonical_json
from omnisort_hw.wire_records import to_wire
from sim_backend.devices import SimCamera, SimCell
from sim_backend.scene import load_scene, sized
from sim_backend.sort_harness import sim_registration_config

BUMPS_DEG = (0.05, 0.1, 0.3, 1.0)
AXES = ("x", "y", "z")
_UNIT = {"x": np.array([1.0, 0, 0]), "y": np.array([0, 1.0, 0]), "z": np.array([0, 0, 1.0])}


def _bump_key(size: float) -> str:
    return f"{size:g}"


def _arm_pose(rng: np.random.Generator, home: np.ndarray, board_B: np.ndarray) -> np.ndarray:
    """A random arm pose: half with the gripper hanging over the floor board (hiding part of
    it), half around home."""
    if rng.random() < 0.5:
        T = np.diag([1.0, -1.0, -1.0, 1.0])
        offset = np.array([rng.uniform(-120, 120), rng.uniform(-150, 150), rng.uniform(150, 350)])
        T[:3, 3] = board_B + offset
        try:
            return nearest_solution(get_model("UR5e"), T, home)
        except Exception:
            pass
    return home + rng.uniform(-1.0, 1.0, 6) * np.array([40.0, 20.0, 30.0, 40.0, 40.0, 90.0])


def drift_trials(
    seed: int = 0,
    scenes: int = 2,
    unmoved: int = 200,
    width: int = 960,
    bumps: tuple[float, ...] = BUMPS_DEG,
    config: WatchdogConfig | None = None,
) -> list[Trial]:
    """One trial per (scene, camera mode). The seeded draws (scene layouts, arm poses) are
    made here, in the order the experiment always made them, and written into each trial's
    configuration; a trial's seed is its simulated cell's noise seed."""
    if scenes < 1 or unmoved < 0:
        raise InputError(f"--scenes must be >= 1 and --unmoved >= 0, got {scenes}, {unmoved}")
    cfg = config or WatchdogConfig()
    rng = np.random.default_rng(seed)
    base = sized(load_scene("sorting"), width)
    home = np.asarray(SortConfig().home_deg, float)
    runs = [(k, degraded) for k in range(scenes) for degraded in (False, True)]
    per_run = [
        unmoved // len(runs) + (1 if i < unmoved % len(runs) else 0) for i in range(len(runs))
    ]
    layouts: dict[int, dict[str, Any]] = {}
    trials = []
    for (k, degraded), n_unmoved in zip(runs, per_run, strict=True):
        if k not in layouts:
            n_cubes = int(rng.integers(2, 5))
            layouts[k] = draw_layout(base, rng, n_cubes, max_angle_deg=5.0)
        reg_cfg = sim_registration_config(apply_layout(base, layouts[k], home))
        T_board = reg_cfg.T_B_board
        board_B = T_board[:3, :3] @ reg_cfg.board.object_points().mean(axis=0) + T_board[:3, 3]

        def pose(draw: bool, board_B: np.ndarray = board_B) -> list[float] | None:
            return [float(v) for v in _arm_pose(rng, home, board_B)] if draw else None

        unmoved_poses = [pose(bool(i % 2)) for i in range(n_unmoved)]
        bump_list = [
            [size, axis, sign, pose(bool(rng.random() < 0.3))]
            for size in bumps
            for axis in AXES
            for sign in (1.0, -1.0)
        ]
        config_k = {
            "scene": k,
            "degraded": degraded,
            "width": width,
            "layout": layouts[k],
            "unmoved_poses": unmoved_poses,
            "bumps": bump_list,
            "watchdog": asdict(cfg),
        }
        trials.append(Trial("drift", config_k, seed * 1000 + 10 * k + int(degraded)))
    return trials


def drift_trial(config: Mapping[str, Any], seed: int) -> TrialOutput:
    """One scene in one camera mode: register, then the unmoved captures and the bumps of
    the configuration (see module docstring). Timing: the checks' timestamps."""
    cfg = WatchdogConfig(**config["watchdog"])
    home = np.asarray(SortConfig().home_deg, float)
    base = sized(load_scene("sorting"), int(config["width"]))
    k, degraded = int(config["scene"]), bool(config["degraded"])
    bump_sizes = list(dict.fromkeys(float(b[0]) for b in config["bumps"]))
    out: dict[str, Any] = {
        "scene": k,
        "degraded": degraded,
        "unmoved_captures": 0,
        "false_alarms": 0,
        "occluded_captures": 0,
        "bumps": {
            _bump_key(b): {"captures": 0, "detected": 0, "max_angle_error_deg": 0.0}
            for b in bump_sizes
        },
        "max_unmoved_angle_deg": 0.0,
        "thresholds_deg": [],
        "failures": [],
        "registration_retries": [],
    }
    checked_at: list[Any] = []
    cell = SimCell(apply_layout(base, config["layout"], home), seed=seed)
    cam = SimCamera(cell, degraded=degraded)
    cam.connect()
    try:
        cell.world.laser_on = False
        cell.world.set_joints(home)
        first = cam.grab(with_truth=True)
        truth = cam.last_truth
        assert truth is not None
        calib = SystemCalibration.from_json(truth, source="truth")
        reg_cfg = sim_registration_config(cell.scene)
        reference = np.asarray(first.image)
        payload = dict(truth)  # the true robot base, unless the registration succeeds
        for _ in range(3):
            try:
                reg = register_from_image(reference, calib, reg_cfg)
            except OmnisortError as exc:
                out["registration_retries"].append(f"scene {k}: {exc}")
                reference = np.asarray(cam.grab().image)
                continue
            payload["robot_base"] = robot_base_record(reg, reg_cfg, "reference")
            break
        R0 = cell.world.R_SC.copy()

        def run_check(true_rotvec: np.ndarray, what: str) -> dict[str, Any]:
            img = np.asarray(cam.grab().image)
            res = check_drift(img, calib, payload, reg_cfg, reference, cfg, what)
            est = np.radians(res.decision.rotvec_deg)
            err = float(np.degrees(np.linalg.norm(est - true_rotvec)))
            b = res.board
            occluded = b is not None and b.n_visible < b.visible.size
            summary: dict[str, Any] = to_wire(res.summary())
            checked_at.append(summary.pop("checked_at", None))
            return {
                "drift": res.drift,
                "err": err,
                "res": res,
                "summary": summary,
                "occluded": occluded,
            }

        for i, pose in enumerate(config["unmoved_poses"]):
            cell.world.set_joints(home if pose is None else np.asarray(pose, float))
            r = run_check(np.zeros(3), f"unmoved {i}")
            out["unmoved_captures"] += 1
            out["occluded_captures"] += int(r["occluded"])
            out["max_unmoved_angle_deg"] = max(
                out["max_unmoved_angle_deg"], r["res"].decision.angle_deg
            )
            out["thresholds_deg"].append(r["res"].decision.threshold_deg)
            if r["drift"]:
                out["false_alarms"] += 1
                out["failures"].append(
                    {"scene": k, "degraded": degraded, "unmoved": i, **r["summary"]}
                )
        cell.world.set_joints(home)
        for size, axis, sign, pose in config["bumps"]:
            cell.world.set_joints(home if pose is None else np.asarray(pose, float))
            cell.bump_camera(sign * size, axis)
            try:
                r = run_check(np.radians(sign * size) * _UNIT[axis], f"bump {size} {axis}")
            finally:
                cell.world.R_SC = R0.copy()
            row = out["bumps"][_bump_key(size)]
            row["captures"] += 1
            row["detected"] += int(r["drift"])
            row["max_angle_error_deg"] = max(row["max_angle_error_deg"], r["err"])
            if not r["drift"]:
                out["failures"].append(
                    {
                        "scene": k,
                        "degraded": degraded,
                        "bump": sign * size,
                        "axis": axis,
                        **r["summary"],
                    }
                )
    finally:
        cam.close()
        cell.close()
    return TrialOutput(json.loads(canonical_json(out)), {"checked_at": checked_at})


def summarize_drift(
    results: Sequence[Mapping[str, Any]], seed: int, width: int, scenes: int, seconds: float
) -> dict[str, Any]:
    """The `--json` object from the trials' results, in manifest order."""
    sizes = list(dict.fromkeys(s for r in results for s in r["bumps"]))
    out: dict[str, Any] = {
        "seed": seed,
        "width": width,
        "scenes": scenes,
        "unmoved_captures": sum(r["unmoved_captures"] for r in results),
        "false_alarms": sum(r["false_alarms"] for r in results),
        "occluded_captures": sum(r["occluded_captures"] for r in results),
        "bumps": {
            s: {
                "captures": sum(r["bumps"][s]["captures"] for r in results),
                "detected": sum(r["bumps"][s]["detected"] for r in results),
                "max_angle_error_deg": round(
                    max(r["bumps"][s]["max_angle_error_deg"] for r in results), 4
                ),
            }
            for s in sizes
        },
        "max_unmoved_angle_deg": round(max(r["max_unmoved_angle_deg"] for r in results), 4),
        "failures": [f for r in results for f in r["failures"]],
        "registration_retries": [m for r in results for m in r["registration_retries"]],
    }
    th = np.asarray([v for r in results for v in r["thresholds_deg"]] or [np.nan])
    out["threshold_deg_median"] = round(float(np.median(th)), 4)
    out["threshold_deg_max"] = round(float(np.max(th)), 4)
    out["seconds"] = round(seconds, 1)
    return out


def evaluate_drift(
    seed: int = 0,
    scenes: int = 2,
    unmoved: int = 200,
    width: int = 960,
    bumps: tuple[float, ...] = BUMPS_DEG,
    config: WatchdogConfig | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run the experiment in this process; returns the `--json` object (see module
    docstring). `progress` is called once per trial, with its scene and mode."""
    trials = drift_trials(seed, scenes, unmoved, width, bumps, config)
    t0 = time.perf_counter()
    results = []
    for trial in trials:
        results.append(drift_trial(trial.config, trial.seed).result)
        if progress:
            mode = "degraded" if trial.config["degraded"] else "clean"
            progress(f"scene {trial.config['scene']} {mode}")
    return summarize_drift(results, seed, width, scenes, time.perf_counter() - t0)
