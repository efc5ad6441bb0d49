"""The paper's Table 3 comparison on simulated data: all four methods, clean and degraded.

Environment: OMNISORT_BENCH_N (configurations, default 35), OMNISORT_BENCH_N_DEGRADED (the
degraded run's, default the same), OMNISORT_BENCH_SEED (default 0).
Rendered datasets are kept in build/bench/ and reused. The simulated camera writes sRGB, as
real cameras and the authors' renders do; the extraction undoes it (`clean_*`, `degraded_*`).
`*_linear_assumed_*` runs the same images through the extraction as it was before it modelled
the tone curve (values taken as linear light): the border-edge bias it leaves.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from omnisort_hw.evaluation.table3 import evaluate_dataset

BUILD = Path(__file__).resolve().parent.parent / "build" / "bench"
DEVELOPMENT_SEEDS = (0,)


def unseen_seeds() -> tuple[list[int], int]:
    """The seeds nothing was tuned on (OMNISORT_BENCH_UNSEEN_SEEDS, comma-separated, default
    "11,12"; the development seed is refused) and the configurations each
    (OMNISORT_BENCH_UNSEEN_N, default 12)."""
    seeds = [int(s) for s in os.environ.get("OMNISORT_BENCH_UNSEEN_SEEDS", "11,12").split(",") if s]
    if any(s in DEVELOPMENT_SEEDS for s in seeds):
        raise ValueError(f"OMNISORT_BENCH_UNSEEN_SEEDS: {DEVELOPMENT_SEEDS} is the tuning seed")
    return seeds, int(os.environ.get("OMNISORT_BENCH_UNSEEN_N", "12"))


def table3_figures(
    n: int,
    seed: int,
    degraded: bool,
    assume: str | None = None,
    effects: bool = False,
    degrade: dict[str, Any] | None = None,
    label: str = "",
) -> dict[str, Any]:
    """Each method's MAE, mean time, z RMS and failures on the Table 3 dataset of these
    parameters (rendered into build/bench/ once; `effects`: through the colour camera;
    `degrade`: [degrade] keys over the scenes', named `label` in the dataset's folder)."""
    from omnisort_hw.core.radiometry import ToneCurve
    from sim_backend.dataset import make_dataset

    suffix = "-effects" if effects else ("-degraded" if degraded else "")
    data = BUILD / (f"table3-n{n}-seed{seed}-srgb{suffix}" + (f"-{label}" if label else ""))
    if not (data / "dataset.json").is_file():
        make_dataset(data, "table3", n, seed, degraded=degraded, effects=effects, degrade=degrade)
    tone = ToneCurve.parse(assume) if assume else None
    result = evaluate_dataset(data, progress=True, tone=tone)
    out: dict[str, Any] = {}
    for method, s in result["methods"].items():
        if "mae" in s:
            out[f"{method}_mae"] = {k: round(v, 4) for k, v in s["mae"].items()}
            out[f"{method}_mean_time_s"] = round(s["mean_time_s"], 3)
        if "z_rms" in s:
            out[f"{method}_std_z_rms"] = {k: round(v, 2) for k, v in s["z_rms"].items()}
        out[f"{method}_failures"] = len(s["failures"])
    out["mapping_max_rel_error_pct"] = (
        round(100 * result["mapping"]["max_rel_error"], 4)
        if result["mapping"]["max_rel_error"] is not None
        else None
    )
    return out


def run(shared: Path) -> dict[str, Any]:
    n = int(os.environ.get("OMNISORT_BENCH_N", "35"))
    n_deg = int(os.environ.get("OMNISORT_BENCH_N_DEGRADED", str(n)))
    seed = int(os.environ.get("OMNISORT_BENCH_SEED", "0"))
    figures: dict[str, Any] = {"configurations": n, "degraded_configurations": n_deg, "seed": seed}
    figures.update({f"clean_{k}": v for k, v in table3_figures(n, seed, False).items()})
    figures.update({f"degraded_{k}": v for k, v in table3_figures(n_deg, seed, True).items()})
    for deg, name in ((False, "clean"), (True, "degraded")):
        before = table3_figures(n_deg if deg else n, seed, deg, assume="linear")
        figures.update({f"{name}_linear_assumed_{k}": v for k, v in before.items() if "mae" in k})
    return figures
