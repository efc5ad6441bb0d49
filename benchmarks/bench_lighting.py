"""Hostile light: single frame against the measurement capture in every scenario, and the
capture's cost (`omnisort evaluate lighting`).

Environment: OMNISORT_BENCH_LIGHT_SEED (default 0), OMNISORT_BENCH_LIGHT_WIDTH (camera size,
default 1920), OMNISORT_BENCH_LIGHT_FRAMES (default 8), OMNISORT_BENCH_LIGHT_CHECK_SEEDS (more
seeds, comma separated, default "5": the same run on a seed nothing was tuned on, summarised),
OMNISORT_BENCH_LIGHT_SMALL_SEEDS (default "11,97,131") at OMNISORT_BENCH_LIGHT_SMALL_WIDTH
(default 1280, the CLI's default camera, where a cube's corner spans fewer pixels), summarised.

`colour_camera`: the check seeds again through a colour camera's effects (crosstalk, chromatic
aberration, bloom, Bayer demosaicing: `evaluate lighting --effects`), summarised beside the
same seeds' plain figures (`check_seeds`). OMNISORT_BENCH_LIGHT_EFFECTS_ONLY=1 keeps the
recorded figures and measures this part alone.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from omnisort_hw.evaluation.lighting import evaluate_lighting


def _r(v: Any, k: int) -> Any:
    return round(float(v), k) if isinstance(v, (int, float)) else v


RESULTS = Path(__file__).resolve().parent / "results.json"


def run(shared: Path) -> dict[str, Any]:
    seed = int(os.environ.get("OMNISORT_BENCH_LIGHT_SEED", "0"))
    width = int(os.environ.get("OMNISORT_BENCH_LIGHT_WIDTH", "1920"))
    frames = int(os.environ.get("OMNISORT_BENCH_LIGHT_FRAMES", "8"))
    checks = os.environ.get("OMNISORT_BENCH_LIGHT_CHECK_SEEDS", "5")
    if os.environ.get("OMNISORT_BENCH_LIGHT_EFFECTS_ONLY") == "1":
        kept = dict(json.loads(RESULTS.read_text())["lighting"])
        return {**kept, "colour_camera": _summaries(checks, frames, width, effects=True)}
    result = evaluate_lighting(seed, frames, width, progress=True)
    figures: dict[str, Any] = {"seed": seed, "width": width, "frames": frames, "scenarios": {}}
    for name, sc in result["scenarios"].items():
        row: dict[str, Any] = {}
        for key in ("single", "capture"):
            e = sc[key]
            if "error" in e:
                row[key] = {"error": e["error"]}
                continue
            mre = e.get("mapping_max_rel_error")
            pmax = e.get("point_max_rel_error")
            rec = e.get("record", {})
            row[key] = {
                "spurious_points": e["spurious_points"],
                "laser_points": e["laser_points"],
                "echoes_dropped": e.get("echoes_dropped", 0),
                "mapping_max_rel_error_pct": _r(100 * mre, 4) if mre is not None else None,
                "point_max_rel_error_pct": _r(100 * pmax, 4) if pmax is not None else None,
                "calibration_max_error_deg": _r(e.get("calibration_max_error_deg"), 4),
                "calibration_distance_error_mm": _r(e.get("calibration_distance_error_mm"), 3),
                "calibration_error": e.get("calibration_error"),
                "capture_s": e.get("capture_s"),
                "wall_s": e.get("wall_s"),
                "re_exposures": rec.get("retries", 0),
                "response_gamma": rec.get("response_gamma"),
            }
        figures["scenarios"][name] = row
    figures["check_seeds"] = _summaries(checks, frames, width)
    figures["colour_camera"] = _summaries(checks, frames, width, effects=True)
    small = int(os.environ.get("OMNISORT_BENCH_LIGHT_SMALL_WIDTH", "1280"))
    seeds = os.environ.get("OMNISORT_BENCH_LIGHT_SMALL_SEEDS", "11,97,131")
    figures["small_width"] = {"width": small, "seeds": _summaries(seeds, frames, small)}
    return figures


def _summaries(seeds: str, frames: int, width: int, effects: bool = False) -> dict[str, Any]:
    """Every scenario on each of the comma-separated `seeds`, summarised per seed
    (`effects`: through the colour camera's effects)."""
    return {
        str(seed): _summary(evaluate_lighting(seed, frames, width, progress=True, effects=effects))
        for seed in (int(x) for x in seeds.split(",") if x.strip())
    }


def _summary(result: dict[str, Any]) -> dict[str, Any]:
    """Per method: spurious points summed over the scenarios, the worst map error."""
    out: dict[str, Any] = {}
    for key in ("single", "capture"):
        entries = [sc[key] for sc in result["scenarios"].values()]
        ok = [e for e in entries if "error" not in e]
        errs = [
            e["mapping_max_rel_error"] for e in ok if e.get("mapping_max_rel_error") is not None
        ]
        out[key] = {
            "failed": len(entries) - len(ok),
            "spurious_points": sum(e["spurious_points"] for e in ok),
            "laser_points": sum(e["laser_points"] for e in ok),
            "mapping_max_rel_error_pct": _r(100 * max(errs), 4) if errs else None,
            "per_scenario": {
                name: [
                    sc[key].get("spurious_points"),
                    _r(100 * (sc[key].get("mapping_max_rel_error") or 0), 4),
                ]
                for name, sc in result["scenarios"].items()
                if "error" not in sc[key]
            },
        }
    return out
