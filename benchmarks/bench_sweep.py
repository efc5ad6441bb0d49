"""Sweeps: the speed-up of a local process pool and of a 2-worker Dask LocalCluster against
serial, on a small Table 3 sweep (each trial renders one configuration's three images and
calibrates them with the five runs), and the time per trial, to size a cluster.

Environment: OMNISORT_BENCH_SWEEP_N (configurations, default 10), OMNISORT_BENCH_SWEEP_WIDTH
(render size, default 960). Each executor runs the same trials from scratch. `*_s`: the
sweep's wall time, the executor's start included (`*_start_s`: starting the cluster; the
pool spawns its workers with the first trials); `*_trial_s_mean`: the trials' own wall time
inside the workers; `*_trial_cpu_s_mean`: their CPU time (what a trial costs a core,
whatever the load). A fresh worker pays the imports and the simulator's first render once;
the serial run pays them once for all. The machine is shared: the load average (1 min)
before and after each run is recorded, and a load above the cores slows the parallel runs
more than the serial one.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

from benchmarks.__main__ import machine
from omnisort_hw.evaluation.table3_trials import table3_trials
from omnisort_hw.sweeps.executors import DaskExecutor, PoolExecutor, SerialExecutor
from omnisort_hw.sweeps.runner import run_sweep
from omnisort_hw.sweeps.trial import canonical_json

N = int(os.environ.get("OMNISORT_BENCH_SWEEP_N", "10"))
WIDTH = int(os.environ.get("OMNISORT_BENCH_SWEEP_WIDTH", "960"))
SEED = 0
WORKERS = 2


def _load() -> float:
    return round(os.getloadavg()[0], 2)


def _timed(make: Any, trials: list[Any]) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    load0 = _load()
    t0 = time.perf_counter()
    with make() as ex:
        started = time.perf_counter() - t0
        rows = run_sweep(trials, executor=ex).rows
    wall = time.perf_counter() - t0
    per_trial = [r["timing"]["wall_s"] for r in rows]
    cpu = [r["timing"]["cpu_s"] for r in rows]
    figures = {
        "s": round(wall, 2),
        "start_s": round(started, 2),
        "trial_s_mean": round(sum(per_trial) / len(per_trial), 2),
        "trial_s_max": round(max(per_trial), 2),
        "trial_cpu_s_mean": round(sum(cpu) / len(cpu), 2),
        "load_before": load0,
        "load_after": _load(),
    }
    return figures, rows


def run(shared: Path) -> dict[str, Any]:
    """Figures of the sweep executors (`shared` is unused: the trials render their images)."""
    del shared
    trials = table3_trials(N, SEED, width=WIDTH)
    out: dict[str, Any] = {
        "experiment": "table3",
        "trials": len(trials),
        "width_px": WIDTH,
        "seed": SEED,
        "workers": WORKERS,
        "cores": os.cpu_count(),
        "cpu": machine()["cpu"],  # this run's machine (the record's `machine` is the others')
    }
    results: dict[str, list[str]] = {}
    runs = (
        ("serial", SerialExecutor),
        ("pool", lambda: PoolExecutor(WORKERS, timeout_s=1800)),
        ("dask", lambda: DaskExecutor(workers=WORKERS, timeout_s=1800)),
    )
    for name, make in runs:
        figures, rows = _timed(make, trials)
        out.update({f"{name}_{k}": v for k, v in figures.items()})
        results[name] = [canonical_json(r["result"]) for r in rows]
    for name in ("pool", "dask"):
        out[f"{name}_speedup"] = round(out["serial_s"] / out[f"{name}_s"], 2)
    # The result rows (timing and provenance aside) are the same on every executor.
    out["identical_results"] = results["pool"] == results["serial"] == results["dask"]
    return out
