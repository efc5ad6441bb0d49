"""UR e-series kinematics: FK against hand-made and independent references; IK round trips."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from omnisort_hw.core.frames import (
    invert_pose,
    pose_from_xyz_rotvec,
    pose_from_xyz_rpy,
    rotation_angle_deg,
    translation_pose,
    xyz_rotvec_from_pose,
    xyz_rpy_from_pose,
)
from omnisort_hw.core.kinematics import (
    UR3E,
    UR5E,
    UR10E,
    UR_MODELS,
    JointLimitError,
    SingularPoseError,
    UnreachableError,
    URModel,
    equivalent_within_limits,
    forward,
    get_model,
    inverse,
    joint_frames,
    nearest_solution,
    nearest_solutions,
    wrap_deg,
)
from omnisort_hw.errors import MotionRefusedError

MODELS = list(UR_MODELS.values())
IDS = [m.name for m in MODELS]
POS_TOL_MM = 1e-6  # 1e-9 m
ROT_TOL = 1e-9  # rad (rotation matrix entries)


def dh_reference(model: URModel, q_deg: np.ndarray) -> np.ndarray:
    """Textbook standard DH: the product of Rz(theta) Tz(d) Tx(a) Rx(alpha) as 4x4 matrices."""
    T = np.eye(4)
    for theta, d, a, alpha in zip(
        np.radians(q_deg), model.d_mm, model.a_mm, model.alpha_rad, strict=True
    ):
        ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
        T = T @ np.array(
            [
                [ct, -st * ca, st * sa, a * ct],
                [st, ct * ca, -ct * sa, a * st],
                [0.0, sa, ca, d],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
    return T


def poe_reference(model: URModel, q_deg: np.ndarray) -> np.ndarray:
    """Product of exponentials with the screw axes read off the zero pose (drawn by hand).

    At q = 0 the arm lies along -x (a2, a3 < 0); joint axes and points on them in B:
    J1 +z through 0; J2, J3, J4 -y through (0, 0, d1), (a2, 0, d1), (a2 + a3, 0, d1);
    J5 -z through (a2 + a3, -d4, d1); J6 -y through (a2 + a3, -d4, d1 - d5).
    """
    d1, _, _, d4, d5, d6 = model.d_mm
    a2, a3 = model.a_mm[1], model.a_mm[2]
    axes = [(0, 0, 1), (0, -1, 0), (0, -1, 0), (0, -1, 0), (0, 0, -1), (0, -1, 0)]
    points = [
        (0, 0, 0),
        (0, 0, d1),
        (a2, 0, d1),
        (a2 + a3, 0, d1),
        (a2 + a3, -d4, d1),
        (a2 + a3, -d4, d1 - d5),
    ]
    M = np.array([[1.0, 0, 0, a2 + a3], [0, 0, -1, -d4 - d6], [0, 1, 0, d1 - d5], [0, 0, 0, 1]])
    T = np.eye(4)
    for w, p, theta in zip(axes, points, np.radians(q_deg), strict=True):
        w = np.array(w, dtype=float)
        v = -np.cross(w, np.array(p, dtype=float))
        W = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
        E = np.eye(4)  # exp of the twist (w, v) * theta, Lynch & Park eq. 3.88
        E[:3, :3] = np.eye(3) + np.sin(theta) * W + (1 - np.cos(theta)) * W @ W
        E[:3, 3] = (
            np.eye(3) * theta + (1 - np.cos(theta)) * W + (theta - np.sin(theta)) * W @ W
        ) @ v
        T = T @ E
    return T @ M


def random_joints(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.uniform(-180.0, 180.0, (n, 6))


# --------------------------------------------------------------------------- model and FK


def test_published_dh_parameters_in_mm() -> None:
    assert UR5E.d_mm == (162.5, 0.0, 0.0, 133.3, 99.7, 99.6)
    assert UR5E.a_mm == (0.0, -425.0, -392.2, 0.0, 0.0, 0.0)
    assert UR3E.d_mm == (151.85, 0.0, 0.0, 131.05, 85.35, 92.1)
    assert UR3E.a_mm == (0.0, -243.55, -213.2, 0.0, 0.0, 0.0)
    assert UR10E.d_mm == (180.7, 0.0, 0.0, 174.15, 119.85, 116.55)
    assert UR10E.a_mm == (0.0, -612.7, -571.55, 0.0, 0.0, 0.0)
    for m in MODELS:
        np.testing.assert_array_equal(m.limits[2], [-180.0, 180.0])
        np.testing.assert_array_equal(m.limits[[0, 1, 3, 4, 5]], [[-360.0, 360.0]] * 5)
    assert get_model("UR5e") is UR5E
    with pytest.raises(ValueError, match="ur10e"):
        get_model("ur7")


def test_model_rejects_non_ur_geometry_and_bad_limits() -> None:
    with pytest.raises(ValueError, match="UR geometry"):
        URModel("x", (1.0, 0, 0, 1, 1, 1), (5.0, -1, -1, 0, 0, 0), UR5E.limits_deg, (1.0,) * 6)
    with pytest.raises(ValueError, match="min < max"):
        UR5E.with_limits([[10.0, -10.0]] * 6)
    tight = UR5E.with_limits([[-90.0, 90.0]] * 6)
    assert tight.limits[0, 1] == 90.0 and UR5E.limits[0, 1] == 360.0


@pytest.mark.parametrize("model", MODELS, ids=IDS)
def test_fk_zero_and_upright_poses_by_hand(model: URModel) -> None:
    d1, _, _, d4, d5, d6 = model.d_mm
    a2, a3 = model.a_mm[1], model.a_mm[2]
    # Zero pose: arm stretched along -x; flange x = a2 + a3, y = -(d4 + d6), z = d1 - d5,
    # tool z along -y of B.
    T = forward(model, np.zeros(6))
    np.testing.assert_allclose(T[:3, 3], [a2 + a3, -(d4 + d6), d1 - d5], atol=1e-9)
    np.testing.assert_allclose(T[:3, :3], [[1, 0, 0], [0, 0, -1], [0, 1, 0]], atol=1e-12)
    # Upright pose (0, -90, 0, -90, 0, 0): upper arm and forearm vertical.
    T = forward(model, np.array([0.0, -90.0, 0.0, -90.0, 0.0, 0.0]))
    np.testing.assert_allclose(T[:3, 3], [0.0, -(d4 + d6), d1 - a2 - a3 + d5], atol=1e-9)
    np.testing.assert_allclose(T[:3, :3], [[-1, 0, 0], [0, 0, -1], [0, -1, 0]], atol=1e-12)


@pytest.mark.parametrize("model", MODELS, ids=IDS)
def test_fk_matches_textbook_dh_and_product_of_exponentials(model: URModel) -> None:
    q = random_joints(np.random.default_rng(1), 50)
    T = forward(model, q)
    for qi, Ti in zip(q, T, strict=True):
        np.testing.assert_allclose(Ti, dh_reference(model, qi), atol=1e-9)
        np.testing.assert_allclose(Ti, poe_reference(model, qi), atol=1e-9)


def test_fk_batch_shapes_tool_and_joint_frames() -> None:
    q = random_joints(np.random.default_rng(2), 6).reshape(2, 3, 6)
    T = forward(UR5E, q)
    assert T.shape == (2, 3, 4, 4)
    assert forward(UR5E, q[0, 0]).shape == (4, 4)
    tool = pose_from_xyz_rpy(np.array([10.0, -5.0, 150.0]), np.array([0.0, 0.0, 45.0]))
    np.testing.assert_allclose(forward(UR5E, q, tool), T @ tool, atol=1e-9)
    frames = joint_frames(UR5E, q)
    assert frames.shape == (2, 3, 7, 4, 4)
    np.testing.assert_allclose(frames[..., 6, :, :], T, atol=1e-9)
    np.testing.assert_allclose(frames[..., 0, :, :], np.broadcast_to(np.eye(4), T.shape))
    # Frame 1 is at the shoulder height on the base axis whatever the joints.
    np.testing.assert_allclose(
        frames[..., 1, :3, 3], np.broadcast_to([0, 0, 162.5], (2, 3, 3)), atol=1e-9
    )


# --------------------------------------------------------------------------- IK


@pytest.mark.parametrize("model", MODELS, ids=IDS)
def test_ik_round_trip_10000_random_poses(model: URModel) -> None:
    rng = np.random.default_rng(sum(map(ord, model.name)))
    q = random_joints(rng, 10_000)
    T = forward(model, q)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no NaN / invalid-value warnings from the solver
        sols = inverse(model, T)
    assert sols.q.shape == (10_000, 8, 6) and sols.valid.shape == (10_000, 8)
    assert sols.valid.sum(axis=1).min() >= 2 and sols.reachable.all()
    assert np.isnan(sols.q[~sols.valid]).all() and np.isfinite(sols.q[sols.valid]).all()
    assert np.all((sols.q[sols.valid] >= -180.0) & (sols.q[sols.valid] < 180.0))
    # Every valid branch reproduces the pose.
    back = forward(model, np.where(sols.valid[..., None], sols.q, 0.0))
    err = np.abs(back - T[:, None])[sols.valid]
    assert err[:, :3, 3].max() < POS_TOL_MM
    assert err[:, :3, :3].max() < ROT_TOL
    # The joints the pose came from are one of the branches, modulo 360 deg.
    diff = np.abs(wrap_deg(sols.q - q[:, None, :])).max(axis=-1)
    assert np.nanmin(np.where(sols.valid, diff, np.inf), axis=1).max() < 1e-6


def test_ik_batch_shape_tool_and_distinct_branches() -> None:
    q = np.array([[10.0, -70.0, 100.0, -120.0, -80.0, 30.0], [-40.0, -100.0, -60.0, 20.0, 50.0, 5]])
    tool = pose_from_xyz_rpy(np.array([0.0, 0.0, 120.0]), np.array([0.0, 0.0, 0.0]))
    T = forward(UR5E, q, tool).reshape(2, 1, 4, 4)
    sols = inverse(UR5E, T, tool=tool)
    assert sols.q.shape == (2, 1, 8, 6) and sols.valid.shape == (2, 1, 8)
    assert sols.valid.all()  # well inside the workspace: all 8 branches exist
    flat = sols.q.reshape(2, 8, 6)
    for row in flat:  # 8 different configurations
        d = np.abs(wrap_deg(row[:, None] - row[None])).max(axis=-1)
        assert np.all(d[~np.eye(8, dtype=bool)] > 1.0)
    single = inverse(UR5E, T[0, 0], tool=tool)
    assert single.q.shape == (8, 6)
    np.testing.assert_allclose(single.q, flat[0])


def test_unreachable_pose_is_reported_not_nan_garbage() -> None:
    far = translation_pose(np.array([[2000.0, 0.0, 300.0], [0.0, 0.0, 0.0], [0.0, 0.0, 162.5]]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sols = inverse(UR5E, far)
    # A flange at the base origin pointing up puts the wrist centre on the base axis, inside
    # the d4 cylinder: also unreachable.
    assert not sols.valid.any() and not sols.reachable.any()
    assert not sols.singular.any()
    with pytest.raises(UnreachableError, match="out of reach"):
        nearest_solution(UR5E, far[0], np.zeros(6))
    q, ok = nearest_solutions(UR5E, far, np.zeros(6))
    assert not ok.any() and np.isnan(q).all()


def test_wrist_singular_pose_keeps_theta6_and_flags() -> None:
    q0 = np.array([20.0, -80.0, 70.0, -60.0, 0.0, 37.0])
    T = forward(UR5E, q0)
    sols = inverse(UR5E, T, q6_hint_deg=q0[5])
    singular_branches = sols.wrist_singular & sols.valid
    assert singular_branches.sum() == 4  # both wrist signs of the shoulder branch with theta5 = 0
    assert not (sols.wrist_singular & ~sols.valid).any()
    back = forward(UR5E, np.where(sols.valid[:, None], sols.q, 0.0))
    assert np.abs(back - T)[sols.valid].max() < POS_TOL_MM
    np.testing.assert_allclose(sols.q[singular_branches][:, 5], q0[5], atol=1e-9)
    near = q0 + 0.5
    near[5] = q0[5]
    np.testing.assert_allclose(nearest_solution(UR5E, T, near), q0, atol=1e-6)
    # Elsewhere wrist 3 stays where it is; the other joints make up for it.
    q = nearest_solution(UR5E, T, q0 + 0.5)
    assert q[5] == pytest.approx(q0[5] + 0.5, abs=1e-9)
    np.testing.assert_allclose(forward(UR5E, q), T, atol=1e-6)
    # Without singular branches the nearest one is on the other shoulder.
    q = nearest_solution(UR5E, T, q0, allow_singular=False)
    assert abs(wrap_deg(q[0] - q0[0])) > 30.0


def test_fully_singular_pose_raises_when_singular_not_allowed() -> None:
    # Upright pose: shoulder (wrist centre on the d4 cylinder), elbow (stretched) and wrist
    # (theta5 = 0) singular at once, on every branch.
    q0 = np.array([0.0, -90.0, 0.0, -90.0, 0.0, 0.0])
    T = forward(UR5E, q0)
    sols = inverse(UR5E, T)
    assert sols.valid.any()
    assert sols.shoulder_singular[sols.valid].all() and sols.elbow_singular[sols.valid].all()
    assert sols.wrist_singular[sols.valid].all()
    back = forward(UR5E, np.where(sols.valid[:, None], sols.q, 0.0))
    assert np.abs(back - T)[sols.valid][:, :3, 3].max() < 1e-4
    with pytest.raises(SingularPoseError, match="singular"):
        nearest_solution(UR5E, T, q0, allow_singular=False)
    q = nearest_solution(UR5E, T, q0)
    np.testing.assert_allclose(forward(UR5E, q), T, atol=1e-4)
    assert issubclass(SingularPoseError, MotionRefusedError)


def test_nearest_solution_picks_the_branch_of_the_current_joints() -> None:
    rng = np.random.default_rng(5)
    q = rng.uniform(-170.0, 170.0, (600, 6))
    # Away from singularities, where two branches meet and either may be nearest.
    q = q[(np.abs(np.sin(np.radians(q[:, [2, 4]]))) > 0.2).all(axis=1)][:300]
    T = forward(UR5E, q)
    current = q + rng.uniform(-3.0, 3.0, q.shape)
    got, ok = nearest_solutions(UR5E, T, current)
    assert ok.all()
    np.testing.assert_allclose(got, q, atol=1e-6)
    for i in range(0, 300, 60):
        np.testing.assert_allclose(nearest_solution(UR5E, T[i], current[i]), got[i], atol=1e-12)


def test_nearest_solution_wraps_to_the_equivalent_angle_within_limits() -> None:
    q = np.array([30.0, -100.0, 80.0, -70.0, -90.0, -5.0])
    T = forward(UR5E, q)
    current = q.copy()
    current[0], current[5] = -325.0, 350.0
    got = nearest_solution(UR5E, T, current)
    assert got[5] == pytest.approx(355.0, abs=1e-6)  # -5 + 360, within +-360 and next to 350
    assert got[0] == pytest.approx(30.0 - 360.0, abs=1e-6)
    # With wrist 3 limited to +-180 the same branch needs -5, although 355 would be nearer.
    lim = UR5E.limits.copy()
    lim[5] = (-180.0, 180.0)
    current[5] = 150.0
    assert nearest_solution(UR5E, T, current, lim)[5] == pytest.approx(-5.0, abs=1e-6)


def test_equivalent_angle_within_limits() -> None:
    wide = np.array([[-360.0, 360.0]] * 6)
    narrow = np.array([[-180.0, 180.0]] * 6)
    q = np.full(6, -175.0)
    np.testing.assert_allclose(equivalent_within_limits(q, np.full(6, 179.0), wide), 185.0)
    np.testing.assert_allclose(equivalent_within_limits(q, np.full(6, 179.0), narrow), -175.0)
    np.testing.assert_allclose(equivalent_within_limits(q, np.full(6, -300.0), wide), -175.0)
    shifted = np.array([[20.0, 400.0]] * 6)
    np.testing.assert_allclose(equivalent_within_limits(np.full(6, 10.0), 0.0, shifted), 370.0)
    assert np.isnan(equivalent_within_limits(np.full(6, 10.0), 0.0, [[20.0, 30.0]] * 6)).all()
    # Broadcasting over poses and branches.
    out = equivalent_within_limits(np.zeros((4, 8, 6)), np.full((4, 1, 6), 350.0), wide)
    np.testing.assert_allclose(out, 360.0)


def test_joint_limits_respected_and_reported() -> None:
    rng = np.random.default_rng(6)
    q = rng.uniform(-170.0, 170.0, (2000, 6))
    T = forward(UR5E, q)
    lim = np.array(
        [
            [-90.0, 90.0],
            [-180.0, 0.0],
            [-150.0, 150.0],
            [-200.0, 200.0],
            [-120.0, 120.0],
            [-360.0, 360.0],
        ]
    )
    got, ok = nearest_solutions(UR5E, T, np.zeros(6), lim)
    assert 0 < ok.sum() < len(ok)
    assert np.all((got[ok] >= lim[:, 0]) & (got[ok] <= lim[:, 1]))
    np.testing.assert_allclose(forward(UR5E, got[ok]), T[ok], atol=1e-6)
    # The refused ones have no branch within the limits at all.
    sols = inverse(UR5E, T[~ok])
    shifted = np.stack([sols.q + 360.0 * k for k in (-1, 0, 1)])
    inside = ((shifted >= lim[:, 0]) & (shifted <= lim[:, 1])).any(axis=0).all(axis=-1)
    assert not (inside & sols.valid).any()
    i = int(np.argmin(ok))
    with pytest.raises(JointLimitError, match="limits"):
        nearest_solution(UR5E, T[i], np.zeros(6), lim)


# --------------------------------------------------------------------------- pose helpers


def test_rpy_is_rz_ry_rx_and_round_trips() -> None:
    T = pose_from_xyz_rpy(np.array([1.0, 2.0, 3.0]), np.array([90.0, 0.0, 90.0]))
    # Rz(90) Rx(90): x -> y, y -> z, z -> x.
    np.testing.assert_allclose(T[:3, :3], [[0, 0, 1], [1, 0, 0], [0, 1, 0]], atol=1e-12)
    rng = np.random.default_rng(7)
    xyz = rng.uniform(-500, 500, (20, 3))
    rpy = rng.uniform(-170, 170, (20, 3)) * [1.0, 0.5, 1.0]
    back_xyz, back_rpy = xyz_rpy_from_pose(pose_from_xyz_rpy(xyz, rpy))
    np.testing.assert_allclose(back_xyz, xyz)
    np.testing.assert_allclose(back_rpy, rpy, atol=1e-9)
    rv = rng.uniform(-100, 100, (20, 3))
    back_xyz, back_rv = xyz_rotvec_from_pose(pose_from_xyz_rotvec(xyz, rv))
    np.testing.assert_allclose(back_rv, rv, atol=1e-9)
    T = pose_from_xyz_rotvec(xyz, rv)
    np.testing.assert_allclose(invert_pose(T) @ T, np.broadcast_to(np.eye(4), T.shape), atol=1e-9)
    assert rotation_angle_deg(T[0, :3, :3], T[0, :3, :3]) == pytest.approx(0.0, abs=1e-12)
    R90 = pose_from_xyz_rpy(np.zeros(3), np.array([0.0, 0.0, 90.0]))[:3, :3]
    assert rotation_angle_deg(np.eye(3), R90) == pytest.approx(90.0)
