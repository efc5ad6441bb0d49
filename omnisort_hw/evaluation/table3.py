"""The paper's Table 3 comparison, reproduced on simulated data with ground truth.

For every configuration of a dataset (see sim_backend.dataset), each method calibrates from its
own image (two-sided: joint and paper; three-sided: method1; checkerboards: method2), with the
camera intrinsics known, as in the paper. One more row, `joint_three_sided`, runs the joint
refinement on method1's image, so the two solvers also meet on the same pixels. Errors against
truth.json give MAE and RMSE per parameter and method; time is extraction + solve per
calibration.

Mapping check: for each configuration, vertical obstacles facing the camera axis at 300 to
1500 mm are cut with the TRUE laser plane, their laser lines projected through the true
camera, and mapped back with the joint calibration; the relative error of the mapped
distance isolates what the calibration contributes to obstacle distances.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.system_calibration import PARAMETERS, SystemCalibration
from omnisort_hw.core.mapping import pixels_to_plane
from omnisort_hw.core.radiometry import ToneCurve
from omnisort_hw.errors import InputError, OmnisortError

# Row of the table -> (method, image it calibrates from). `joint_three_sided` is the joint
# refinement on method1's image: the same solver against method1 on the same pixels.
RUNS = {
    "joint": ("joint", "two_sided"),
    "paper": ("paper", "two_sided"),
    "method1": ("method1", "three_sided"),
    "method2": ("method2", "checkerboards"),
    "joint_three_sided": ("joint", "three_sided"),
}
TARGET_OF = {
    "two_sided": "two-sided",
    "three_sided": "three-sided",
    "checkerboards": "checkerboards",
}
MAPPING_DISTANCES_MM = (300.0, 600.0, 900.0, 1200.0, 1500.0)
MAPPING_BEARINGS_DEG = (0.0, 90.0, 180.0, 270.0)


_TRUTH_MARKERS = {
    "border.near": "border_near",
    "border.far": "border_far",
    "low.near": "floor_near",
    "low.far": "floor_far",
}
_INNER_FACE = {"left": "wall_left.+x", "right": "wall_right.-x"}


def features_from_truth(truth: dict[str, Any], points: int = 100) -> Any:
    """Two-sided target features made from the simulator's truth instead of the image: border
    and wall/floor lines projected from the wall geometry, the exact laser polylines on the
    inner faces, the marker centres. With them a method's error is the solver's alone."""
    from omnisort_hw.core.features import TargetFeatures, WallFeatures

    model = OcamModel.from_dict(truth["camera"])
    R = np.asarray(truth["camera_rotation"]["matrix"], float)
    s = np.linspace(0.05, 0.95, points)[:, None]
    walls = {}
    for wall in truth["target"]["walls"]:
        a, b = np.asarray(wall["border_segment_S_mm"], float)
        floor_z = float(truth["target"]["floor_z_mm"])
        fa, fb = a.copy(), b.copy()
        fa[2] = fb[2] = floor_z
        laser = [
            np.asarray(p["points_px"], float)
            for p in truth["laser_polylines_px"]
            if p["surface"] == _INNER_FACE[wall["name"]]
        ]
        walls[wall["name"]] = WallFeatures(
            border_px=model.ray_to_pixel((a + s * (b - a)) @ R),
            laser_px=np.concatenate(laser) if laser else np.zeros((0, 2)),
            markers_px={
                _TRUTH_MARKERS[m["name"]]: np.asarray(m["center_px"], float)
                for m in truth["markers_px"]
                if m["wall"] == wall["name"]
            },
            floor_px=model.ray_to_pixel((fa + s * (fb - fa)) @ R),
        )
    return TargetFeatures("two-sided", model.image_size, walls)


def truth_parameters(truth: dict[str, Any]) -> dict[str, float]:
    cr, lp = truth["camera_rotation"], truth["laser_plane"]
    return {
        "cam_roll_deg": cr["roll_deg"],
        "cam_pitch_deg": cr["pitch_deg"],
        "cam_yaw_deg": cr["yaw_deg"],
        "laser_roll_deg": lp["roll_deg"],
        "laser_pitch_deg": lp["pitch_deg"],
        "laser_distance_mm": lp["distance_mm"],
    }


def run_entry(calib: SystemCalibration, truth: dict[str, Any]) -> dict[str, Any]:
    """One calibration against truth: signed errors in PARAMETERS' order, and the reported
    std where the method gives one for every parameter."""
    want, got = truth_parameters(truth), calib.parameters()
    entry: dict[str, Any] = {"error": [got[k] - want[k] for k in PARAMETERS]}
    if all(k in calib.std for k in PARAMETERS):
        entry["std"] = [float(calib.std[k]) for k in PARAMETERS]
    return entry


@dataclass
class MethodStats:
    errors: list[np.ndarray] = field(default_factory=list)
    times: list[float] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)
    stds: list[np.ndarray] = field(default_factory=list)  # reported std, where a method has one

    def add(self, calib: SystemCalibration, truth: dict[str, Any], seconds: float) -> None:
        """Count one calibration: its time, its signed errors and its reported std."""
        self.add_run(run_entry(calib, truth), seconds)

    def add_run(self, run: dict[str, Any], seconds: float | None) -> None:
        """Count one calibration of a configuration's row (`calibrate_config`)."""
        if "failure" in run:
            self.failures.append(run["failure"])
            return
        if seconds is not None:
            self.times.append(seconds)
        self.errors.append(np.asarray(run["error"], float))
        if "std" in run:
            self.stds.append(np.asarray(run["std"], float))

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {"n": len(self.errors), "failures": self.failures}
        if self.errors:
            e = np.abs(np.array(self.errors))
            out["mae"] = {k: float(v) for k, v in zip(PARAMETERS, e.mean(axis=0), strict=True)}
            out["rmse"] = {
                k: float(v) for k, v in zip(PARAMETERS, np.sqrt((e**2).mean(axis=0)), strict=True)
            }
            out["max"] = {k: float(v) for k, v in zip(PARAMETERS, e.max(axis=0), strict=True)}
            if self.times:
                out["mean_time_s"] = float(np.mean(self.times))
        if self.stds and len(self.stds) == len(self.errors):
            # Normalised errors: ~1 when the reported standard deviations are honest.
            z = np.array(self.errors) / np.maximum(np.array(self.stds), 1e-12)
            out["z_rms"] = {
                k: float(v) for k, v in zip(PARAMETERS, np.sqrt((z**2).mean(axis=0)), strict=True)
            }
        return out


def mapping_errors(calib: SystemCalibration, truth_sys: SystemCalibration) -> np.ndarray:
    """Relative distance errors of obstacles at MAPPING_DISTANCES_MM (see module docstring)."""
    rel = []
    n, d = truth_sys.laser_normal, truth_sys.laser_distance_mm
    for dist in MAPPING_DISTANCES_MM:
        for bearing in np.radians(MAPPING_BEARINGS_DEG):
            normal = np.array([np.cos(bearing), np.sin(bearing), 0.0])
            along = np.array([-np.sin(bearing), np.cos(bearing), 0.0])
            s = np.linspace(-150.0, 150.0, 31)
            base = dist * normal + s[:, None] * along  # on the obstacle face, at Z = 0
            # Walk down the vertical to the true laser plane: n.(p - (0, 0, -d)) = 0.
            z = -d - (base @ n) / n[2]
            pts = base + z[:, None] * np.array([0.0, 0.0, 1.0])
            rays_C = pts @ truth_sys.R_SC
            if not np.all(truth_sys.model.in_view(rays_C)):
                continue
            px = truth_sys.model.ray_to_pixel(rays_C)
            mapped = pixels_to_plane(px, calib)
            # What `omnisort map` reports: the nearest horizontal distance from the camera axis.
            measured = float(np.nanmin(np.hypot(mapped[:, 0], mapped[:, 1])))
            rel.append(abs(measured - dist) / dist)
    return np.array(rel)


def _calibrate(
    method: str,
    scene: str,
    image_path: Path,
    model: OcamModel,
    truth: dict[str, Any],
    tone: ToneCurve,
) -> Any:
    from omnisort_hw.pipeline.extrinsics import calibrate_system
    from omnisort_hw.pipeline.image_files import read_image

    image = read_image(image_path)
    target = TARGET_OF[scene]
    if target == "checkerboards":
        boards = truth.get("checkerboards") or []
        board = tuple(boards[0]["inner_corners"]) if boards else (9, 6)
        square = float(boards[0]["square_mm"]) if boards else 97.0
        return calibrate_system(
            image,
            model,
            target,
            method,
            board=board,
            square_mm=square,
            source=str(image_path),
            tone=tone,
        )
    sep = float(truth["target"]["separation_mm"])
    return calibrate_system(
        image, model, target, method, separation_mm=sep, source=str(image_path), tone=tone
    )


def calibrate_config(
    folder: Path, tone: ToneCurve, calibrated: Callable[[], None] | None = None
) -> tuple[dict[str, Any], dict[str, float]]:
    """Every run of RUNS on one configuration's images: (result, seconds per run). The
    result holds, per run, the signed errors against truth in PARAMETERS' order, the reported
    std where the method has one, and for `joint` the mapping check's relative errors; or the
    failure. Paths inside messages are made relative to `folder`, so the result does not
    depend on where the images were."""
    runs: dict[str, Any] = {}
    seconds: dict[str, float] = {}
    for row, (method, scene) in RUNS.items():
        truth = json.loads((folder / f"{scene}.truth.json").read_text())
        model = OcamModel.from_dict(truth["camera"], source=str(folder / scene))
        t0 = time.perf_counter()
        try:
            calib = _calibrate(method, scene, folder / f"{scene}.png", model, truth, tone)
        except OmnisortError as exc:
            text = str(exc).replace(str(folder.parent) + "/", "")
            runs[row] = {"failure": f"{folder.name}: {text}"}
        else:
            seconds[row] = time.perf_counter() - t0
            entry = run_entry(calib, truth)
            if row == "joint":
                rel = mapping_errors(calib, SystemCalibration.from_json(truth))
                entry["mapping_rel"] = [float(v) for v in rel]
            runs[row] = entry
        if calibrated is not None:
            calibrated()
    return {"folder": folder.name, "runs": runs}, seconds


def summarize_table3(
    rows: Sequence[tuple[dict[str, Any], dict[str, float] | None]],
    dataset: str,
    seed: int | None,
    degraded: bool,
) -> dict[str, Any]:
    """The comparison's summary from `calibrate_config` rows (result, seconds), in
    configuration order: per method MAE, RMSE, max, z_rms, mean time, failures; the mapping
    check's worst and mean relative errors."""
    stats = {m: MethodStats() for m in RUNS}
    mapping: list[np.ndarray] = []
    for result, seconds in rows:
        for name in RUNS:
            run = result["runs"][name]
            stats[name].add_run(run, None if seconds is None else seconds.get(name))
            if name == "joint" and "mapping_rel" in run:
                mapping.append(np.asarray(run["mapping_rel"], float))
    rel = np.concatenate(mapping) if mapping else np.zeros(0)
    return {
        "dataset": dataset,
        "n": len(rows),
        "seed": seed,
        "degraded": degraded,
        "methods": {m: s.summary() for m, s in stats.items()},
        "mapping": {
            "distances_mm": list(MAPPING_DISTANCES_MM),
            "max_rel_error": float(rel.max()) if rel.size else None,
            "mean_rel_error": float(rel.mean()) if rel.size else None,
            "samples": int(rel.size),
        },
    }


def evaluate_dataset(
    data_dir: str | Path,
    progress: bool = True,
    tone: ToneCurve | None = None,
    first: int | None = None,
) -> dict[str, Any]:
    """Run every method on every configuration of a rendered dataset; return the summary.
    `tone`: the tone curve the extraction assumes; by default the simulated camera's, as the
    dataset records it (datasets from before the record were rendered linear). `first`: only
    the first configurations (to compare with a partial run)."""
    from tqdm import tqdm

    root = Path(data_dir)
    index_path = root / "dataset.json"
    if not index_path.is_file():
        raise InputError(f"{index_path}: no dataset here (render one with omnisort sim dataset)")
    index = json.loads(index_path.read_text())
    tone = tone or ToneCurve.parse(index.get("tone_curve", "linear"))
    configs = index["configs"][:first]
    with tqdm(
        total=len(configs) * len(RUNS), desc="calibrating", unit="cal", disable=not progress
    ) as bar:
        rows = [
            calibrate_config(root / cfg["folder"], tone, lambda: bar.update(1)) for cfg in configs
        ]
    return summarize_table3(rows, str(root), index.get("seed"), index.get("degraded", False))


PUBLISHED_MAE = {
    "proposed (paper)": {
        "cam_pitch_deg": 0.05,
        "cam_roll_deg": 0.13,
        "cam_yaw_deg": 0.06,
        "laser_pitch_deg": 0.14,
        "laser_roll_deg": 0.09,
        "time_s": 28.39,
    },
    "method 1 (paper)": {
        "cam_pitch_deg": 0.06,
        "cam_roll_deg": 0.12,
        "cam_yaw_deg": 0.06,
        "laser_pitch_deg": 0.16,
        "laser_roll_deg": 0.12,
        "time_s": 33.99,
    },
    "method 2 (paper)": {
        "cam_pitch_deg": 0.11,
        "cam_roll_deg": 0.15,
        "cam_yaw_deg": 0.09,
        "laser_pitch_deg": 0.29,
        "laser_roll_deg": 0.08,
        "time_s": 25.41,
    },
}


def format_table(result: dict[str, Any]) -> str:
    """The comparison as a text table: MAE (RMSE) per parameter and method, and time."""
    cols = list(PARAMETERS)
    head = ["method"] + [c.replace("_deg", " deg").replace("_mm", " mm") for c in cols]
    width = max(17, *(len(n) for n in [*result["methods"], *PUBLISHED_MAE]))

    def row(cells: list[str]) -> str:
        return " | ".join(f"{x:>{width}}" for x in cells)

    lines = [row([*head, "time s", "fail"])]
    for name, s in result["methods"].items():
        if "mae" not in s:
            lines.append(
                f"{name:>{width}} | no successful calibration ({len(s['failures'])} failed)"
            )
            continue
        # Four decimals: the wall methods' errors are thousandths of a degree.
        cells = [f"{s['mae'][c]:.4f} ({s['rmse'][c]:.4f})" for c in cols]
        lines.append(row([name, *cells, f"{s['mean_time_s']:.3f}", str(len(s["failures"]))]))
    for name, pub in PUBLISHED_MAE.items():
        cells = [f"{pub[c]:.2f}" if c in pub else "-" for c in cols]
        lines.append(row([name, *cells, f"{pub['time_s']:.2f}", ""]))
    m = result["mapping"]
    if m["max_rel_error"] is not None:
        lines.append(
            f"mapping (joint): max relative distance error {100 * m['max_rel_error']:.3f}%"
            f" over {m['samples']} obstacles at 300-1500 mm"
        )
    return "\n".join(lines)
