"""`evaluate_drift` at a small size: the `--json` keys the issue names, the counts adding up,
no false alarm on an unmoved camera and every 0.3 deg knock found."""

from __future__ import annotations

import pytest

pytest.importorskip("pybullet")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]


def test_small_drift_experiment() -> None:
    from omnisort_hw.evaluation.drift import AXES, evaluate_drift

    res = evaluate_drift(seed=5, scenes=1, unmoved=4, width=480, bumps=(0.3,))
    assert res["unmoved_captures"] == 4
    assert res["false_alarms"] == 0, res["failures"]
    row = res["bumps"]["0.3"]
    assert row["captures"] == 2 * len(AXES) * 2  # clean and degraded, both signs
    assert row["detected"] == row["captures"], res["failures"]
    assert row["max_angle_error_deg"] < 0.02
    assert set(row) == {"captures", "detected", "max_angle_error_deg"}
