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
            "cycle": {
                "picks": 3,
                "motion_s": 18.0,
                "gripper_s": 1.2,
                "wait_s": 0.3,
                "planned_s": 17.1,
                "locate_s": 0.9,
                "plans": 3,
                "plan_ms_mean": 50.0,
                "plan_ms_max": 80.0,
            },
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
            "cycle": {
                "picks": 3,
                "motion_s": 21.0,
                "gripper_s": 1.2,
                "wait_s": 0.0,
                "planned_s": 20.1,
                "locate_s": 0.9,
                "plans": 4,
                "plan_ms_mean": 100.0,
                "plan_ms_max": 120.0,
            },
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
    # Cycle figures are totals over all picks, not means of the scenes' means.
    assert out["motion_s_per_pick"] == pytest.approx(39.0 / 6)
    assert out["wait_s_per_pick"] == pytest.approx(0.05)
    assert out["lower_bound_s_per_pick"] == pytest.approx(37.2 / 6)
    cycle = (39.0 + 2.4 + 0.3) / 6
    assert out["picks_per_minute"] == pytest.approx(60.0 / cycle, abs=0.01)
    assert out["plan_ms_per_pick"] == pytest.approx((150.0 + 400.0) / 7, abs=0.1)
    assert out["plan_ms_max"] == 120.0
