"""The random-scene sorting experiment's totals."""

from __future__ import annotations

import pytest

pytest.importorskip("pybullet", reason="the experiment runs on the simulated cell")

from omnisort_hw.evaluation.sorting import SUMMARY_KEYS, summarize_sorting


def test_evaluation_totals_have_the_documented_keys() -> None:
    rows = [
        {
            "scene": 0,
            "cubes": 3,
            "sorted_ok": 3,
            "collisions": 0,
            "position_errors_mm": [0.5, 1.0],
            "registration_error_mm": 0.4,
            "registration_error_deg": 0.01,
            "motion_s_per_pick": 9.0,
            "wall_s_per_pick": 3.0,
        },
        {
            "scene": 1,
            "cubes": 4,
            "sorted_ok": 3,
            "collisions": 1,
            "position_errors_mm": [1.5],
            "registration_error_mm": 0.6,
            "registration_error_deg": 0.02,
            "motion_s_per_pick": 10.0,
            "wall_s_per_pick": 4.0,
            "skipped": ["unreachable"],
        },
    ]
    out = summarize_sorting(rows, 12.0, 0, 960, "truth")
    # Every figure the CLI and the benchmark print.
    for key in (*SUMMARY_KEYS, "wall_s"):
        assert key in out, key
    assert out["cubes"] == 7 and out["sorted_ok"] == 6 and out["collisions"] == 1
    assert out["success_rate"] == pytest.approx(6 / 7, abs=1e-4)
    assert out["mean_position_error_mm"] == pytest.approx(1.0)
    assert out["not_sorted"][0]["scene"] == 1
