"""The simulated cell's sort harness: the contact monitor sees a crash."""

from __future__ import annotations

from typing import Any

import pytest

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")

from sim_backend.sort_harness import SimVerifier
from tests.pipeline.sorting_scene import sorting_scene


@pytest.fixture
def arm() -> Any:
    from sim_backend.devices import SimArm, SimCell

    cell = SimCell.from_scene(sorting_scene(), width=320)
    arm = SimArm(cell)
    arm.connect()
    yield arm
    arm.close()
    cell.close()


def test_collision_monitor_sees_a_crash(arm: Any) -> None:
    verifier = SimVerifier(arm, check_every=1)
    verifier.start()
    try:
        # Sweep the arm down through the red bin and into the floor beside it.
        arm.move_joints([90.0, -30.0, 100.0, -70.0, 90.0, 0.0], speed_deg_s=180.0)
    finally:
        verifier.stop()
    hits = " ".join(verifier.collisions)
    assert "bin_0_red" in hits and "floor" in hits, verifier.collisions
