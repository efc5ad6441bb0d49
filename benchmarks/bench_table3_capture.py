"""Table 3 measured with captures (`omnisort evaluate table3 --degraded --frames N`) against
the clean renders of the same configurations and seeds, at the same camera size.

Environment: OMNISORT_BENCH_N (configurations, default 35), OMNISORT_BENCH_SEED (default 0),
OMNISORT_BENCH_FRAMES (default 8), OMNISORT_BENCH_CAPTURE_WIDTH (default 1920, the size of
the rendered Table 3). The clean reference is calibrated from the render each capture is
exposed from (the clean dataset's bytes), so both cover the same configurations. The run's
raw result and every target's capture are kept in build/bench/ and reused;
OMNISORT_BENCH_CAPTURE_REEVAL=1 measures the kept captures again (a change to the extraction
or the solvers, without exposing again); OMNISORT_BENCH_CAPTURE_PARTIAL=1 records an
unfinished run as it stands (`configurations_done` says how far it got);
OMNISORT_BENCH_CAPTURE_UNSEEN_ONLY=1 keeps the recorded development-seed figures and
measures the unseen seeds alone.

The goal is absolute (the ratio to clean is shown, no longer a goal): `joint` MAE at most
GOAL_DEG on every angle and GOAL_MM on the laser distance, checked on seeds nothing was
tuned on: OMNISORT_BENCH_UNSEEN_SEEDS (comma-separated, default "11,12"; seed 0, the
development seed, is refused), OMNISORT_BENCH_UNSEEN_N configurations each (default 12).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from benchmarks.bench_table3 import unseen_seeds
from omnisort_hw.evaluation.table3_capture import evaluate_captures, evaluate_kept
from sim_backend.dataset import table3_configs

BUILD = Path(__file__).resolve().parent.parent / "build" / "bench"
GOAL_DEG = 0.01
GOAL_MM = 0.1


def _goal(mae: dict[str, float]) -> bool:
    """Whether a joint MAE record meets the absolute goal."""
    return all(v <= (GOAL_MM if k.endswith("_mm") else GOAL_DEG) for k, v in mae.items())


def _unseen(frames: int, width: int) -> dict[str, Any]:
    """joint (and the others) on the unseen seeds, with the goal's verdict per seed."""
    seeds, n = unseen_seeds()
    out: dict[str, Any] = {"configurations": n, "goal_deg": GOAL_DEG, "goal_mm": GOAL_MM}
    for seed in seeds:
        name = f"table3-capture-n{n}-seed{seed}-f{frames}-w{width}"
        raw, keep = BUILD / f"{name}.json", BUILD / name
        result = json.loads(raw.read_text()) if raw.is_file() else None
        if result is None or result.get("done") != n:
            result = evaluate_captures(
                n, seed, frames, width, progress=True, partial=raw, keep=keep
            )
        entry: dict[str, Any] = {}
        for method, s in result["methods"].items():
            entry[f"{method}_failures"] = len(s["failures"])
            if "mae" in s:
                entry[f"{method}_mae"] = {k: round(v, 4) for k, v in s["mae"].items()}
        joint = result["methods"]["joint"]
        entry["joint_goal_met"] = bool(
            "mae" in joint and not joint["failures"] and _goal(joint["mae"])
        )
        out[str(seed)] = entry
    return out


def run(shared: Path) -> dict[str, Any]:
    n = int(os.environ.get("OMNISORT_BENCH_N", "35"))
    seed = int(os.environ.get("OMNISORT_BENCH_SEED", "0"))
    frames = int(os.environ.get("OMNISORT_BENCH_FRAMES", "8"))
    width = int(os.environ.get("OMNISORT_BENCH_CAPTURE_WIDTH", "1920"))
    if os.environ.get("OMNISORT_BENCH_CAPTURE_UNSEEN_ONLY") == "1":
        # the development seed's figures as recorded, the unseen seeds measured now
        recorded = json.loads((Path(__file__).parent / "results.json").read_text())
        out = dict(recorded["table3_capture"])
        out["unseen_seeds"] = _unseen(frames, width)
        out["joint_goal_met_seed0"] = _goal(out["capture_joint_mae"])
        return out
    name = f"table3-capture-n{n}-seed{seed}-f{frames}-w{width}"
    raw, keep = BUILD / f"{name}.json", BUILD / name
    result = json.loads(raw.read_text()) if raw.is_file() else None
    partial_ok = os.environ.get("OMNISORT_BENCH_CAPTURE_PARTIAL") == "1"
    if os.environ.get("OMNISORT_BENCH_CAPTURE_REEVAL") == "1":
        # every configuration kept (by this run or by shards of it, `evaluate_captures(only=)`)
        configs = [c.folder for c in table3_configs(n, seed)]
        kept = evaluate_kept(keep, configs, frames, progress=True)
        result = {**(result or {}), **kept, "seed": seed, "width": width}
        raw.write_text(json.dumps(result))
    elif result is None or "clean" not in result or (result.get("done") != n and not partial_ok):
        result = evaluate_captures(n, seed, frames, width, progress=True, partial=raw, keep=keep)
    done = int(result.get("done", n))
    clean = result["clean"]
    out: dict[str, Any] = {
        "configurations": n,
        "configurations_done": done,
        "seed": seed,
        "frames": frames,
        "width": width,
        "mean_capture_s": round(result["capture"]["mean_capture_s"], 3),
        "run_wall_s": result.get("wall_s"),
        "re_exposures": result["capture"]["re_exposures"],
        "mapping_max_rel_error_pct": round(100 * result["mapping"]["max_rel_error"], 4),
        "clean_mapping_max_rel_error_pct": round(100 * clean["mapping"]["max_rel_error"], 4),
    }
    for method, s in result["methods"].items():
        out[f"capture_{method}_failures"] = len(s["failures"])
        c = clean["methods"][method]
        if "mae" not in s or "mae" not in c:
            continue
        out[f"capture_{method}_mae"] = {k: round(v, 4) for k, v in s["mae"].items()}
        out[f"clean_{method}_mae"] = {k: round(v, 4) for k, v in c["mae"].items()}
        out[f"{method}_ratio_to_clean"] = {
            k: round(v / max(c["mae"][k], 1e-9), 2) for k, v in s["mae"].items()
        }
    if os.environ.get("OMNISORT_BENCH_UNSEEN_SEEDS") != "":
        out["unseen_seeds"] = _unseen(frames, width)
    if "capture_joint_mae" in out:
        out["joint_goal_met_seed0"] = _goal(out["capture_joint_mae"])
    return out
