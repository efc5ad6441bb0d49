"""Table 3 as a sweep: one trial per configuration renders its three images on the worker
(in a temporary folder, deleted after) and calibrates them with every method.

The trial's images are the ones `make_dataset` renders for the same (n, seed): the same
configuration angles (`table3_configs`) and per-image noise seeds (`render_config`), so the
rows reproduce `evaluate_dataset` on that dataset exactly (tests/evaluation/
test_table3_trials.py). Timing (seconds per calibration) is kept apart from the result.
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from omnisort_hw.core.radiometry import ToneCurve
from omnisort_hw.evaluation.table3 import calibrate_config, summarize_table3
from omnisort_hw.sweeps.trial import Trial, TrialOutput


def table3_trials(
    n: int,
    seed: int,
    width: int | None = None,
    degraded: bool = False,
    tone_curve: str = "srgb",
    assume_tone_curve: str | None = None,
) -> list[Trial]:
    """The experiment's n configurations as trials (seed: the dataset's)."""
    from sim_backend.dataset import table3_configs

    settings = {
        "width": width,
        "degraded": degraded,
        "tone_curve": tone_curve,
        "assume_tone_curve": assume_tone_curve,
    }
    return [Trial("table3", {**asdict(c), **settings}, seed) for c in table3_configs(n, seed)]


def table3_trial(config: Mapping[str, Any], seed: int) -> TrialOutput:
    """Render one configuration and calibrate it (see module docstring)."""
    from sim_backend.dataset import Table3Config, render_config, table3_bases

    cfg = Table3Config(
        int(config["index"]),
        *(float(config[k]) for k in ("camera_roll", "camera_pitch", "camera_yaw")),
        *(float(config[k]) for k in ("laser_roll", "laser_pitch")),
    )
    bases = table3_bases(config["width"], config["tone_curve"])
    tone = ToneCurve.parse(config["assume_tone_curve"] or config["tone_curve"])
    with tempfile.TemporaryDirectory(prefix="omnisort-table3-") as tmp:
        folder = Path(tmp) / cfg.folder
        render_config(folder, cfg, bases, seed, bool(config["degraded"]))
        result, seconds = calibrate_config(folder, tone)
    return TrialOutput(result, {"calibration_s": seconds})


def summarize_rows(rows: Sequence[Mapping[str, Any]], dataset: str) -> dict[str, Any]:
    """`evaluate_dataset`'s summary from a sweep's table3 rows (manifest order)."""
    pairs = [(r["result"], r["timing"].get("calibration_s")) for r in rows]
    first: Mapping[str, Any] = rows[0] if rows else {"seed": None, "config": {"degraded": False}}
    return summarize_table3(pairs, dataset, first["seed"], bool(first["config"]["degraded"]))
