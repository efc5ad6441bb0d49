"""The drift measurement on renders of the simulated cell with a known camera turn.

480 px renders keep this fast; the tolerance is the issue's (implied angle within 0.02 deg of
the true turn), the false-alarm rate the watchdog's default."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from omnisort_hw.core import drift

pytest.importorskip("pybullet", reason="renders need the simulated cell")
pytestmark = pytest.mark.timeout(300)

WIDTH = 480
AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


@pytest.fixture(scope="module")
def cell() -> Iterator[object]:
    from sim_backend.devices import SimCell

    c = SimCell.from_scene("sorting", seed=3, width=WIDTH, height=WIDTH)
    yield c
    c.close()


def _render(cell: object, seed: int, degraded: bool = True) -> np.ndarray:
    img, _ = cell.render(seed, degraded, laser_on=False)  # type: ignore[attr-defined]
    return img


def _bumped(cell: object, angle_deg: float, axis: str, seed: int) -> np.ndarray:
    world = cell.world  # type: ignore[attr-defined]
    R0 = world.R_SC.copy()
    cell.bump_camera(angle_deg, axis)  # type: ignore[attr-defined]
    try:
        return _render(cell, seed)
    finally:
        world.R_SC = R0


def test_unmoved_camera_with_fresh_noise_is_not_drift(cell: object) -> None:
    R_SC = cell.world.R_SC  # type: ignore[attr-defined]
    ref = _render(cell, 1)
    for seed in (2, 3):
        est = drift.estimate_rotation(ref, _render(cell, seed), cell.model, R_SC)  # type: ignore[attr-defined]
        d = drift.decide(est)
        assert not d.drift, d
        assert d.angle_deg < 0.01
        assert est.blocks >= 12


@pytest.mark.parametrize("axis", sorted(AXES))
def test_a_tenth_of_a_degree_is_detected_and_measured_on_every_axis(
    cell: object, axis: str
) -> None:
    R_SC = cell.world.R_SC.copy()  # type: ignore[attr-defined]
    ref = _render(cell, 1)
    img = _bumped(cell, 0.1, axis, 7)
    est = drift.estimate_rotation(ref, img, cell.model, R_SC)  # type: ignore[attr-defined]
    d = drift.decide(est)
    assert d.drift, d
    truth = np.radians(0.1) * np.asarray(AXES[axis])
    assert np.degrees(np.linalg.norm(est.rotvec_S - truth)) < 0.02
    # The noise-derived threshold (worst direction) at this coarse size; at 960 px it is half.
    assert d.threshold_deg < 0.08


def test_board_hidden_in_part_is_checked_on_its_visible_corners() -> None:
    from omnisort_hw.core.kinematics import get_model, nearest_solution
    from omnisort_hw.core.pick_planning import SortConfig
    from sim_backend.devices import SimCell
    from sim_backend.sort_harness import sim_registration_config

    # 960 px: the 40 mm squares of the floor board are ~7 px wide (3.5 px at 480).
    cell = SimCell.from_scene("sorting", seed=3, width=960, height=960)

    world = cell.world  # type: ignore[attr-defined]
    rc = sim_registration_config(cell.scene)  # type: ignore[attr-defined]
    img, truth = cell.render(1, False, laser_on=False, with_truth=True)  # type: ignore[attr-defined]
    T_SB = np.asarray(truth["robot_base"]["matrix"], float)
    full = drift.measure_board(img, cell.model, world.R_SC, T_SB, rc.T_B_board, rc.board)  # type: ignore[attr-defined]
    assert full.n_visible == rc.board.cols * rc.board.rows
    # The gripper hanging over the board's middle.
    T = np.diag([1.0, -1.0, -1.0, 1.0])
    centre = rc.T_B_board[:3, :3] @ rc.board.object_points().mean(axis=0) + rc.T_B_board[:3, 3]
    T[:3, 3] = centre + np.array([0.0, 0.0, 200.0])
    home = np.asarray(SortConfig().home_deg, float)
    q0 = world.joints()
    world.set_joints(nearest_solution(get_model("UR5e"), T, home))
    try:
        hidden, _ = cell.render(2, True, laser_on=False)  # type: ignore[attr-defined]
    finally:
        world.set_joints(q0)
    part = drift.measure_board(hidden, cell.model, world.R_SC, T_SB, rc.T_B_board, rc.board)  # type: ignore[attr-defined]
    assert 6 <= part.n_visible < full.n_visible
    # Visible corners agree with the true prediction within the detector's noise at 480 px
    # (a pixel spans ~0.2 deg), and the implied base shift is a few mm at most.
    assert np.median(np.linalg.norm(part.residual_px, axis=1)) < 0.5
    assert part.base_shift_mm < 5.0
    cell.close()
