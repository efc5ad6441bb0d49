"""Motion planning: timed joint and linear moves within limits, refusals, collision checks."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from omnisort_hw.core.collision import (
    Box,
    Capsule,
    CollisionError,
    FloorPlane,
    arm_capsules,
    check_collisions,
    collision_mask,
    find_collision,
    require_collision_free,
)
from omnisort_hw.core.frames import rotation_angle_deg
from omnisort_hw.core.kinematics import (
    UR5E,
    UR10E,
    JointLimitError,
    SingularPoseError,
    UnreachableError,
    forward,
    inverse,
    joint_frames,
    wrap_deg,
)
from omnisort_hw.core.motion import (
    MotionLimits,
    Trajectory,
    concatenate,
    offset_pose,
    plan_approach,
    plan_joint_move,
    plan_linear_move,
    plan_retreat,
)
from omnisort_hw.errors import MotionRefusedError

HOME = np.array([0.0, -90.0, 90.0, -90.0, -90.0, 0.0])  # tool pointing down, in front of the base
REL = 1e-6  # relative slack on limit checks: floating point only


def fd_velocity(tr: Trajectory) -> np.ndarray:
    """Average velocity over each sample interval; never exceeds the true peak speed."""
    return np.diff(tr.q, axis=0) / np.diff(tr.t)[:, None]


def fd_acceleration(tr: Trajectory) -> np.ndarray:
    """Second differences: a B-spline-weighted average of the true acceleration."""
    dt = np.diff(tr.t)
    v = np.diff(tr.q, axis=0) / dt[:, None]
    return 2.0 * np.diff(v, axis=0) / (dt[1:] + dt[:-1])[:, None]


def assert_uniform_sampling(tr: Trajectory, rate: float) -> None:
    assert tr.t[0] == 0.0
    np.testing.assert_allclose(np.diff(tr.t), 1.0 / rate, rtol=1e-12)


# --------------------------------------------------------------------------- joint moves


@pytest.mark.parametrize(
    "q1",
    [
        HOME + np.array([120.0, 20.0, -30.0, 40.0, 10.0, -200.0]),
        HOME + np.array([2.0, -1.0, 0.5, 0.0, 0.0, 1.0]),
    ],
    ids=["trapezoid", "triangle"],
)
def test_joint_move_limits_ends_and_synchronisation(q1: np.ndarray) -> None:
    lim = MotionLimits(joint_speed_deg_s=(60, 60, 90, 120, 120, 150), joint_acc_deg_s2=100.0)
    tr = plan_joint_move(HOME, q1, lim)
    assert tr.kind == "joint" and tr.q.shape == (len(tr), 6)
    np.testing.assert_array_equal(tr.q[0], HOME)
    np.testing.assert_array_equal(tr.q[-1], q1)
    assert_uniform_sampling(tr, lim.rate_hz)
    v, a = fd_velocity(tr), fd_acceleration(tr)
    assert np.all(np.abs(v) <= lim.joint_speed * (1 + REL))
    assert np.all(np.abs(a) <= lim.joint_acc * (1 + REL))
    # All joints follow the same normalised profile: a straight line in joint space.
    moving = q1 != HOME
    frac = (tr.q - HOME)[:, moving] / (q1 - HOME)[moving]
    np.testing.assert_allclose(frac, np.broadcast_to(frac[:, :1], frac.shape), atol=1e-12)
    # Not needlessly slow: the limiting joint uses nearly all of its speed or acceleration.
    use = max(np.max(np.abs(v) / lim.joint_speed), np.max(np.abs(a) / lim.joint_acc))
    assert use > 0.9
    assert np.all(np.diff(frac[:, 0]) >= 0.0)  # no overshoot, no reversal


def test_joint_move_minimum_time_by_hand() -> None:
    # One joint moves 90 deg at 60 deg/s, 120 deg/s^2: 0.5 s and 15 deg for each ramp,
    # 60 deg cruising (1 s), 2 s in all, a whole number of sample periods.
    lim = MotionLimits(joint_speed_deg_s=60.0, joint_acc_deg_s2=120.0, rate_hz=100.0)
    tr = plan_joint_move(np.zeros(6), np.array([90.0, 0, 0, 0, 0, 0]), lim)
    assert tr.duration == pytest.approx(2.0, abs=1e-9)
    i = round(0.5 * lim.rate_hz)
    assert tr.q[i, 0] == pytest.approx(15.0, abs=1e-9)  # 0.5 * 120 * 0.5**2


def test_joint_move_zero_length_and_model_checks() -> None:
    tr = plan_joint_move(HOME, HOME)
    assert len(tr) == 1 and tr.duration == 0.0
    np.testing.assert_array_equal(tr.q[0], HOME)
    fast = MotionLimits(joint_speed_deg_s=300.0, joint_acc_deg_s2=1000.0)
    tr = plan_joint_move(HOME, HOME + np.array([100.0, 0, 0, 0, 0, 0]), fast, model=UR10E)
    assert np.abs(fd_velocity(tr)[:, 0]).max() <= 120.0 * (1 + REL)  # UR10e base: 120 deg/s
    with pytest.raises(JointLimitError, match="joint 3"):
        plan_joint_move(HOME, HOME + np.array([0, 0, 100.0, 0, 0, 0]), model=UR5E)
    with pytest.raises(ValueError, match="positive"):
        MotionLimits(joint_speed_deg_s=(60, 60, 60, 60, 60, 0))


# --------------------------------------------------------------------------- linear moves


def line_target(
    dxyz: tuple[float, float, float], rot_deg: tuple[float, float, float]
) -> np.ndarray:
    T = forward(UR5E, HOME)
    T[:3, 3] += dxyz
    T[:3, :3] = T[:3, :3] @ Rotation.from_euler("xyz", rot_deg, degrees=True).as_matrix()
    return T


@pytest.mark.parametrize(
    ("dxyz", "rot"),
    [
        ((-250.0, 200.0, -150.0), (20.0, -10.0, 30.0)),
        ((0.0, 0.0, 0.0), (0.0, 0.0, 90.0)),
        ((300.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    ],
    ids=["translate+rotate", "rotate-only", "translate-only"],
)
def test_linear_move_stays_on_line_and_within_limits(
    dxyz: tuple[float, float, float], rot: tuple[float, float, float]
) -> None:
    lim = MotionLimits(
        joint_speed_deg_s=45.0,
        joint_acc_deg_s2=90.0,
        linear_speed_mm_s=300.0,
        linear_acc_mm_s2=1000.0,
        angular_speed_deg_s=45.0,
        rate_hz=250.0,
    )
    T0, T1 = forward(UR5E, HOME), line_target(dxyz, rot)
    tr = plan_linear_move(UR5E, HOME, T1, lim)
    assert tr.kind == "linear"
    np.testing.assert_array_equal(tr.q[0], HOME)
    assert_uniform_sampling(tr, lim.rate_hz)
    T = forward(UR5E, tr.q)
    np.testing.assert_allclose(T[-1], T1, atol=1e-9)
    # Positions on the segment, orientations on the slerp at the same fraction.
    p0, p1 = T0[:3, 3], T1[:3, 3]
    length = np.linalg.norm(p1 - p0)
    ang = rotation_angle_deg(T0[:3, :3], T1[:3, :3])
    if length > 0:
        u = (p1 - p0) / length
        rel = T[:, :3, 3] - p0
        along = rel @ u
        off_line = np.linalg.norm(rel - along[:, None] * u, axis=1)
        assert off_line.max() < 1e-6
        assert along.min() > -1e-6 and along.max() < length + 1e-6
        s = along / length
    else:
        np.testing.assert_allclose(T[:, :3, 3], np.broadcast_to(p0, (len(tr), 3)), atol=1e-6)
        s = rotation_angle_deg(T0[:3, :3], T[:, :3, :3]) / ang
    slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([T0[:3, :3], T1[:3, :3]])))
    assert rotation_angle_deg(slerp(np.clip(s, 0, 1)).as_matrix(), T[:, :3, :3]).max() < 1e-6
    # Cartesian speed and acceleration along the path, angular speed, joint limits.
    dt = 1.0 / lim.rate_hz
    if length > 0:
        assert np.abs(np.diff(along) / dt).max() <= lim.linear_speed_mm_s * (1 + REL)
        assert np.abs(np.diff(along, 2) / dt**2).max() <= lim.linear_acc_mm_s2 * (1 + REL)
    step_angle = rotation_angle_deg(T[:-1, :3, :3], T[1:, :3, :3])
    assert step_angle.max() / dt <= lim.angular_speed_deg_s * (1 + REL)
    assert np.abs(fd_velocity(tr)).max() <= 45.0 * (1 + REL)
    assert np.abs(fd_acceleration(tr)).max() <= 90.0 * (1 + REL)
    # Continuity: every sample is the IK branch nearest the previous sample.
    sols = inverse(UR5E, T[1:])
    dist = np.abs(wrap_deg(sols.q - tr.q[:-1, None, :])).max(axis=-1)
    nearest = np.nanargmin(np.where(sols.valid, dist, np.inf), axis=1)
    chosen = np.abs(wrap_deg(tr.q[1:, None, :] - sols.q)).max(axis=-1)
    assert np.all(chosen[np.arange(len(nearest)), nearest] < 1e-6)


def test_linear_move_of_a_tool_centre_point() -> None:
    tool = np.eye(4)
    tool[:3, 3] = (0.0, 40.0, 150.0)  # an offset gripper tip
    T0 = forward(UR5E, HOME, tool)
    T1 = T0.copy()
    T1[:3, 3] += (-100.0, 150.0, -100.0)
    T1[:3, :3] = T1[:3, :3] @ Rotation.from_euler("z", 40.0, degrees=True).as_matrix()
    tr = plan_linear_move(UR5E, HOME, T1, tool=tool)
    tcp = forward(UR5E, tr.q, tool)
    np.testing.assert_allclose(tcp[-1], T1, atol=1e-9)
    u = (T1[:3, 3] - T0[:3, 3]) / np.linalg.norm(T1[:3, 3] - T0[:3, 3])
    rel = tcp[:, :3, 3] - T0[:3, 3]
    assert np.linalg.norm(rel - (rel @ u)[:, None] * u, axis=1).max() < 1e-6
    # The flange itself does not move on a straight line when the tool turns.
    flange = forward(UR5E, tr.q)[:, :3, 3] - forward(UR5E, HOME)[:3, 3]
    assert np.linalg.norm(flange - (flange @ u)[:, None] * u, axis=1).max() > 1.0


def test_linear_move_is_limited_by_joints_when_they_bind() -> None:
    T1 = line_target((-250.0, 200.0, -150.0), (20.0, -10.0, 30.0))
    fast = plan_linear_move(
        UR5E, HOME, T1, MotionLimits(joint_speed_deg_s=180.0, joint_acc_deg_s2=1000.0)
    )
    slow_lim = MotionLimits(joint_speed_deg_s=10.0, joint_acc_deg_s2=1000.0)
    slow = plan_linear_move(UR5E, HOME, T1, slow_lim)
    assert slow.duration > 1.5 * fast.duration
    peak = np.abs(fd_velocity(slow)).max()
    assert 0.9 * 10.0 < peak <= 10.0 * (1 + REL)


def test_linear_move_through_wrist_singularity_is_refused() -> None:
    qa = np.array([0.0, -90.0, 90.0, -90.0, 10.0, 0.0])
    qb = np.array([0.0, -90.0, 90.0, -90.0, -10.0, 0.0])
    with pytest.raises(SingularPoseError, match=r"singular|jump"):
        plan_linear_move(UR5E, qa, forward(UR5E, qb))


def test_linear_move_ending_near_wrist_singularity_is_refused() -> None:
    q_end = np.array([0.0, -90.0, 90.0, -90.0, 0.5, 0.0])  # |sin theta5| < the default 0.02
    with pytest.raises(SingularPoseError, match="wrist singularity"):
        plan_linear_move(UR5E, q_end + np.array([0, 0, 0, 0, 30.0, 0]), forward(UR5E, q_end))
    q_ok = np.array([0.0, -90.0, 90.0, -90.0, 5.0, 0.0])
    tr = plan_linear_move(UR5E, q_ok + np.array([0, 0, 0, 0, 30.0, 0]), forward(UR5E, q_ok))
    np.testing.assert_allclose(tr.q[-1], q_ok, atol=1e-6)


def test_linear_moves_respect_tight_joint_acceleration() -> None:
    """Loose Cartesian limits, tight joint limits: the joints' curvature terms must count."""
    rng = np.random.default_rng(11)
    lim = MotionLimits(
        joint_speed_deg_s=20.0,
        joint_acc_deg_s2=30.0,
        linear_speed_mm_s=1000.0,
        linear_acc_mm_s2=5000.0,
        angular_speed_deg_s=200.0,
        angular_acc_deg_s2=1000.0,
        rate_hz=500.0,
    )
    planned = 0
    for _ in range(12):
        q0 = HOME + rng.uniform(-30.0, 30.0, 6)
        T1 = forward(UR5E, q0)
        T1[:3, 3] += rng.uniform(-150.0, 150.0, 3)
        T1[:3, :3] = T1[:3, :3] @ Rotation.from_rotvec(rng.uniform(-0.4, 0.4, 3)).as_matrix()
        try:
            tr = plan_linear_move(UR5E, q0, T1, lim)
        except MotionRefusedError:
            continue
        planned += 1
        assert np.abs(fd_velocity(tr)).max() <= 20.0 * (1 + REL)
        assert np.abs(fd_acceleration(tr)).max() <= 30.0 * (1 + REL)
    assert planned >= 8


def test_linear_move_unreachable_and_joint_limits() -> None:
    far = line_target((-900.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    with pytest.raises(UnreachableError, match="workspace"):
        plan_linear_move(UR5E, HOME, far)
    lim = UR5E.limits.copy()
    lim[0] = (-20.0, 20.0)
    sideways = line_target((300.0, -400.0, 0.0), (0.0, 0.0, 0.0))
    with pytest.raises(JointLimitError, match="joint 1"):
        plan_linear_move(UR5E, HOME, sideways, joint_limits_deg=lim)
    tr = plan_linear_move(UR5E, HOME, forward(UR5E, HOME))
    assert len(tr) == 1


# --------------------------------------------------------------------------- approach, retreat


def test_offset_pose_approach_and_retreat() -> None:
    target = forward(UR5E, HOME)
    target[:3, 3] += (-50.0, 100.0, -300.0)  # tool pointing down, 300 mm lower
    above = offset_pose(target, 100.0)
    np.testing.assert_allclose(above[:3, 3], target[:3, 3] + [0, 0, 100.0], atol=1e-9)
    np.testing.assert_allclose(offset_pose(target, 100.0, np.array([0, 0, 2.0])), above)
    np.testing.assert_array_equal(above[:3, :3], target[:3, :3])
    move, descend = plan_approach(UR5E, HOME, target, 100.0)
    assert move.kind == "joint" and descend.kind == "linear"
    np.testing.assert_allclose(forward(UR5E, move.q[-1]), above, atol=1e-6)
    np.testing.assert_array_equal(descend.q[0], move.q[-1])
    path = forward(UR5E, descend.q)[:, :3, 3]
    np.testing.assert_allclose(
        path[:, :2], np.broadcast_to(target[:2, 3], (len(path), 2)), atol=1e-6
    )
    np.testing.assert_allclose(path[-1], target[:3, 3], atol=1e-9)
    up = plan_retreat(UR5E, descend.q[-1], 150.0, direction=np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(
        forward(UR5E, up.q[-1])[:3, 3], target[:3, 3] + [0, 0, 150.0], atol=1e-9
    )
    whole = concatenate([move, descend, up])
    assert whole.kind == "sequence"
    assert whole.duration == pytest.approx(move.duration + descend.duration + up.duration)
    assert len(whole) == len(move) + len(descend) + len(up) - 2
    assert np.all(np.diff(whole.t) > 0)
    with pytest.raises(ValueError, match="do not join"):
        concatenate([up, move])


# --------------------------------------------------------------------------- collisions


def sweep() -> Trajectory:
    """Base turns 90 deg: the tool (pointing down at z = 488) sweeps a quarter circle."""
    return plan_joint_move(HOME, HOME + np.array([90.0, 0, 0, 0, 0, 0]))


def box_at(centre: tuple[float, float, float], half: float, name: str = "box") -> Box:
    c = np.asarray(centre)
    return Box(tuple(c - half), tuple(c + half), name)


def test_box_in_the_path_is_found_and_clear_path_passes() -> None:
    tr = sweep()
    mid = forward(UR5E, tr.q[len(tr) // 2])[:3, 3]
    blocker = box_at((mid[0], mid[1], mid[2] - 60.0), 40.0, "bin")
    idx = check_collisions(UR5E, tr.q, [blocker, FloorPlane()])
    assert idx is not None and 0.25 * len(tr) < idx < 0.5 * len(tr)
    mask = collision_mask(UR5E, tr.q, [blocker])
    assert mask[idx] and not mask[:idx].any()
    hit = find_collision(UR5E, tr.q, [FloorPlane(), blocker])
    assert hit is not None and hit.index == idx and hit.obstacle == "bin"
    with pytest.raises(CollisionError, match="bin"):
        require_collision_free(UR5E, tr, [blocker])
    # The same box on the far side of the base, or well below the tool: no collision.
    far = box_at((-mid[0], -mid[1], mid[2]), 40.0)
    low = box_at((mid[0], mid[1], 150.0), 40.0)
    assert check_collisions(UR5E, tr.q, [far, low, FloorPlane()]) is None
    assert check_collisions(UR5E, tr.q, []) is None


def test_thin_obstacle_between_samples_is_found_by_subdivision() -> None:
    q = np.stack([HOME, HOME + np.array([90.0, 0, 0, 0, 0, 0])])
    mid = forward(UR5E, HOME + np.array([45.0, 0, 0, 0, 0, 0]))[:3, 3]
    wall = box_at(tuple(mid), 5.0, "wall")
    assert not collision_mask(UR5E, q, [wall]).any()
    assert check_collisions(UR5E, q, [wall]) == 1
    assert check_collisions(UR5E, q, [wall], max_step_deg=1000.0) is None


def test_floor_plane_and_tool_capsule() -> None:
    floor = FloorPlane()
    assert not collision_mask(UR5E, HOME, [floor])[0]  # the base stands on the floor
    reach_down = HOME + np.array([0.0, 45.0, 30.0, 0.0, 0.0, 0.0])
    assert forward(UR5E, reach_down)[2, 3] < 0.0
    assert collision_mask(UR5E, reach_down, [floor])[0]
    # A 400 mm high table under the tool: the arm at home clears it by ~40 mm, a 100 mm
    # gripper does not, nor does the arm with a 60 mm safety margin.
    table = Box((-700.0, -400.0, 0.0), (-300.0, 100.0, 400.0), "table")
    gripper = Capsule(6, (0.0, 0.0, 0.0), (0.0, 0.0, 100.0), 20.0, "gripper")
    assert not collision_mask(UR5E, HOME, [table, floor])[0]
    hit = find_collision(UR5E, HOME[None], [floor, table], tool_capsules=[gripper])
    assert hit is not None and hit.link == "gripper" and hit.obstacle == "table"
    assert collision_mask(UR5E, HOME, [table], margin_mm=60.0)[0]
    # F 500 mm up and turned -90 deg about y: its plane z_F = 0 is x = 0 in B, solid where
    # x > 0, which the shoulder (radius 75 mm about the base axis) crosses.
    wall = np.array([[0.0, 0, -1, 0], [0, 1, 0, 0], [1, 0, 0, 500.0], [0, 0, 0, 1]])
    assert collision_mask(UR5E, HOME, [FloorPlane(wall, "wall")])[0]
    wall[0, 3] = 100.0  # moved to x = 100: clear of the 75 mm shoulder
    assert not collision_mask(UR5E, HOME, [FloorPlane(wall, "wall")])[0]


def test_sphere_cover_contains_the_capsules_and_is_tight() -> None:
    """Point obstacles against exact point-to-capsule distances: no misses, little excess."""
    rng = np.random.default_rng(3)
    q = np.array([10.0, -70.0, 80.0, -100.0, -80.0, 20.0])
    frames = joint_frames(UR5E, q)
    caps = list(arm_capsules(UR5E))
    a = np.array([frames[c.frame] @ [*c.start_mm, 1.0] for c in caps])[:, :3]
    b = np.array([frames[c.frame] @ [*c.end_mm, 1.0] for c in caps])[:, :3]
    r = np.array([c.radius_mm for c in caps])
    # Points scattered around the capsules' surfaces, 0.5 to 1.5 radii from the axes.
    k = rng.integers(0, len(caps), 1500)
    axis_pt = a[k] + rng.uniform(0, 1, (1500, 1)) * (b[k] - a[k])
    direction = rng.normal(size=(1500, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    pts = axis_pt + direction * (r[k] * rng.uniform(0.5, 1.5, 1500))[:, None]
    ab = b - a
    f = np.clip(np.einsum("pkj,kj->pk", pts[:, None] - a, ab) / np.sum(ab * ab, axis=1), 0, 1)
    dist = np.linalg.norm(pts[:, None] - (a + f[..., None] * ab), axis=-1) - r  # signed
    gap = np.min(dist / r, axis=1)
    inside, outside = gap < 0.0, gap > 0.13
    assert inside.sum() > 300 and outside.sum() > 100
    hits = np.array([check_collisions(UR5E, q, [Box(tuple(p), tuple(p))]) == 0 for p in pts])
    assert hits[inside].all()
    assert not hits[outside].any()


def test_broad_phase_gives_the_answer_of_testing_every_sphere() -> None:
    """The two-stage box test reports, sample by sample, exactly what testing every covering
    sphere against every box and the floor reports (random postures, boxes around the arm)."""
    rng = np.random.default_rng(11)
    lim = UR5E.limits
    q = rng.uniform(lim[:, 0], lim[:, 1], (400, 6))
    centres = rng.uniform([-700, -700, 0], [700, 700, 700], (12, 3))
    half = rng.uniform(20, 150, (12, 3))
    obstacles: list[Box | FloorPlane] = [
        Box(tuple(centres[i] - half[i]), tuple(centres[i] + half[i]), f"box {i}")
        for i in range(len(centres))
    ]
    obstacles.insert(5, FloorPlane(np.eye(4), "floor"))
    tool = (Capsule(6, (0.0, -75.0, 60.0), (0.0, 75.0, 60.0), 38.0, "gripper"),)
    capsules = (*arm_capsules(UR5E), *tool)
    from omnisort_hw.core.collision import _cover, _hits

    sp = _cover(capsules)
    F = joint_frames(UR5E, q)[:, sp.frame]
    pts = np.einsum("ckij,kj->cki", F[..., :3, :3], sp.centre) + F[..., :3, 3]
    r = sp.radius + 10.0
    brute = np.zeros((len(q), sp.radius.size, len(obstacles)), bool)
    for j, o in enumerate(obstacles):
        if isinstance(o, Box):
            near = np.clip(pts, o.lo_mm, o.hi_mm)
            brute[:, :, j] = np.sum((pts - near) ** 2, axis=-1) <= r * r
        else:
            brute[:, :, j] = (pts[..., 2] < r) & ~sp.static
    hit, who, what = _hits(UR5E, q, obstacles, capsules, 10.0)
    assert 50 < hit.sum() < len(q) - 50  # both outcomes are exercised
    np.testing.assert_array_equal(hit, brute.any(axis=(1, 2)))
    # Every reported pair is a real contact of that capsule with that obstacle.
    for i in np.flatnonzero(hit):
        assert brute[i, sp.owner == who[i], what[i]].any()
