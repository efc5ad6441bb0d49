"""Table 3 through the colour camera (issue 56's real light): every method on renders with the
camera's effects (crosstalk, chromatic aberration, bloom, Bayer demosaicing, on top of the
sensor's noise: `scene.with_camera_effects`) against the clean renders of the same
configurations, on seeds nothing was tuned on.

The goal: the joint calibration's MAE through the colour camera within GOAL_RATIO of its clean
MAE on each parameter, per seed (`joint_within_goal`); the ratios are given for every method.

Environment: OMNISORT_BENCH_UNSEEN_SEEDS (comma-separated, default "11,12"; seed 0, the
development seed, is refused), OMNISORT_BENCH_UNSEEN_N configurations each (default 12). The
datasets are kept in build/bench/ and reused (bench_table3's naming, suffix `-effects`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from benchmarks.bench_table3 import table3_figures

GOAL_RATIO = 2.0
DEVELOPMENT_SEEDS = (0,)


def ratios(clean: dict[str, float], other: dict[str, float]) -> dict[str, float | None]:
    """Each parameter's MAE over its clean MAE (None where the clean one rounds to 0)."""
    return {k: round(other[k] / v, 2) if v > 0 else None for k, v in clean.items()}


def run(shared: Path) -> dict[str, Any]:
    seeds = [int(s) for s in os.environ.get("OMNISORT_BENCH_UNSEEN_SEEDS", "11,12").split(",") if s]
    if any(s in DEVELOPMENT_SEEDS for s in seeds):
        raise ValueError(f"OMNISORT_BENCH_UNSEEN_SEEDS: {DEVELOPMENT_SEEDS} is the tuning seed")
    n = int(os.environ.get("OMNISORT_BENCH_UNSEEN_N", "12"))
    out: dict[str, Any] = {"configurations": n, "seeds": seeds, "goal_ratio": GOAL_RATIO}
    for seed in seeds:
        clean = table3_figures(n, seed, degraded=False)
        effects = table3_figures(n, seed, degraded=True, effects=True)
        entry: dict[str, Any] = {}
        for key, value in effects.items():
            if key.endswith("_mae") and key in clean:
                method = key.removesuffix("_mae")
                entry[f"{method}_clean_mae"] = clean[key]
                entry[f"{method}_effects_mae"] = value
                entry[f"{method}_ratio"] = ratios(clean[key], value)
            elif key.endswith("_failures"):
                entry[f"{key.removesuffix('_failures')}_effects_failures"] = value
        joint = entry.get("joint_ratio", {})
        entry["joint_within_goal"] = bool(
            joint
            and all(r is not None and r <= GOAL_RATIO for r in joint.values())
            and entry.get("joint_effects_failures", 1) == 0
        )
        out[str(seed)] = entry
    return out
