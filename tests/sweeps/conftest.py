"""A small, fast sweep shared by the executor and resume tests: four hostile-light scenarios
at 256 px, one frame pair, no calibration (a few seconds each), and its rows run serially."""

from __future__ import annotations

from typing import Any

import pytest

pytest.importorskip("pybullet", reason="the trials run on the simulated cell")

SCENARIOS = ("sunlight", "red_objects", "saturated", "specular")
SEED, FRAMES, WIDTH = 3, 1, 256


@pytest.fixture(scope="session")
def small_trials() -> list[Any]:
    from omnisort_hw.evaluation.lighting import lighting_trials

    return lighting_trials(SEED, FRAMES, WIDTH, SCENARIOS, calibrate=False)


@pytest.fixture(scope="session")
def serial_rows(small_trials: list[Any]) -> list[dict[str, Any]]:
    """The sweep run in this process: the reference every other way of running it must
    reproduce."""
    from omnisort_hw.sweeps.runner import run_sweep

    run = run_sweep(small_trials)
    assert run.ran == len(small_trials)
    return run.rows
