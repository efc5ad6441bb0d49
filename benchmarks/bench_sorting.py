"""Sorting on the simulated cell: the random-scene experiment of issue 6, at benchmark size.

Each scene: the sorting cell with the camera turned by up to +-10 deg about each axis, 3 to 6
cubes of random colours (red, green, blue, black), positions and yaws, one bin per colour.
The robot is registered from the image, the cubes located, picked and placed through the
device interfaces, and the result verified from the simulator's state (cube in the bin of its
colour; any contact of the arm or of a held cube with anything else counts as a collision).
`omnisort evaluate sorting --scenes 50` runs the full experiment; here n is smaller so the
benchmark fits in a few minutes (OMNISORT_BENCH_SORT_SCENES overrides it). Two calibrations:
the truth, and the truth with the joint method's typical errors added ("perturbed").

Cycle (per pick, over all picks): `motion_s_per_pick` is the arm's motion time on the arm's
clock (the simulator's), `gripper_s_per_pick` its grasps and releases, `wait_s_per_pick` the
computation the arm waited for (wall time: the first plan of a scene and any plan not ready
when the previous pick ended; the next pick is planned while the arm moves),
`lower_bound_s_per_pick` the planned paths' time at the configured limits, `picks_per_minute`
60 / (motion + gripper + wait). `plan_ms_per_pick` is each plan's CPU time in the run;
`planning_*` the same planning alone on 8 scenes from the true cube poses (one thread, CPU
time, so the machine's load does not count). `wall_s_per_pick` is the computer's time per pick
in the simulator (rendering, registration, location, planning, physics), on this machine.

`colour_*`: the true calibration's scenes again, each seen through a real colour camera (the
sensor's noise, blur and JPEG with crosstalk, chromatic aberration, bloom and Bayer
demosaicing: `evaluate sorting --effects`) instead of clean renders.
OMNISORT_BENCH_SORT_EFFECTS_ONLY=1 keeps the recorded figures and measures this run alone.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from omnisort_hw.evaluation.sorting import SUMMARY_KEYS, evaluate_sorting, planning_only

N_TRUTH = int(os.environ.get("OMNISORT_BENCH_SORT_SCENES", "10"))
N_PERTURBED = max(1, N_TRUTH // 2)
WIDTH = 960
RESULTS = Path(__file__).resolve().parent / "results.json"
RUNS = (("truth", N_TRUTH, False), ("perturbed", N_PERTURBED, False), ("colour", N_TRUTH, True))


def run(shared: Path) -> dict[str, Any]:
    """Figures of the sorting experiment (`shared` is unused: the scenes are generated)."""
    del shared
    out: dict[str, Any] = {"width_px": WIDTH, "seed": 7}
    runs = RUNS
    if os.environ.get("OMNISORT_BENCH_SORT_EFFECTS_ONLY") == "1":
        out = dict(json.loads(RESULTS.read_text())["sorting"])
        runs = tuple(r for r in RUNS if r[2])
    for name, n, effects in runs:
        calibration = "truth" if effects else name
        res = evaluate_sorting(
            scenes=n, seed=7, width=WIDTH, calibration=calibration, effects=effects
        )
        for key in SUMMARY_KEYS:
            out[f"{name}_{key}"] = res[key]
        for stage, secs in res["stage_wall_s_per_scene"].items():
            out[f"{name}_stage_s_{stage}"] = secs
        out[f"{name}_not_sorted"] = res["not_sorted"]
    if len(runs) < len(RUNS):
        return out
    for key, value in planning_only(scenes=8, seed=7).items():
        out[f"planning_{key}"] = value
    return out
